"""OpenSCENARIO XML in and out, laid out like esmini's ScenarioEngine (docs/openscenario.md,
docs/architecture.md). The import: `importer.import_xosc` (one `Translate` class composed of
each module's part: `reader`, `params`, `entities`, `roads`, `positions`, `actions*`,
`conditions`, `storyboard`, `carla`, `sidefile`), element registries in `registry.py` listed
as data by `coverage.py`. Logical scenarios (ParameterValueDistribution files) in
`distribution.py` (a distribution and its template -> one `.addt` with a sweep) and
`distribution_export.py` (a sweep -> a ParameterValueDistribution). This package's own import
stays light: the exporter imports `sidefile` from it."""
