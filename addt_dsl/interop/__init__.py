"""OpenSCENARIO and OpenDRIVE in and out (docs/openscenario.md)."""

# The logical-scenario importer registers itself with openscenario.importer.DOCUMENT_KINDS, so that
# `import_xosc` of a ParameterValueDistribution translates it with the template it names.
from addt_dsl.interop.openscenario import distribution  # noqa: F401
