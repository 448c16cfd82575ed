"""A plan's sweep out: the template (`export_run` of the sweep's first run) and a
ParameterValueDistribution that names it (docs/openscenario.md, "Logical scenarios").

- A sweep of `grid` axes alone (no sampler, no repeat, no `assume`): `Deterministic`, one
  `DistributionSet` per axis and one `ValueSetDistribution` per `cases` axis; OpenSCENARIO
  multiplies them as the sweep does.
- Anything else (a `random`, `halton` or `lhs` sampler, `repeat`, or assumptions that skip
  cells): the concrete runs, as one `ValueSetDistribution` with a parameter value set per
  run. OpenSCENARIO's `Stochastic` draws with the player's own generator (and has no
  quasi-random sequences, repeats or constraints between parameters), so no stochastic
  form gives back the sweep's runs; the value sets do, exactly. The note says which.

Values are written with `repr` (SI units, as OpenSCENARIO's): an import reads back the same
floats, so the runs of an import of the export are the sweep's runs.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from addt_dsl.interop.xodr_export import ExportError, xml_text
from addt_dsl.interop.xosc_export import OSC_MINOR, creation_date, export_run
from addt_dsl.interop.xosc_import import MAX_XML_BYTES
from addt_dsl.plan import ScenarioPlan, SweepPlan
from addt_dsl.sweep import SweepStream, axis_params, sampled_params


PARAMETRIC_KEY = "parametric_plan"  # the side file's copy of the scenario with its parameters (no sweep)


@dataclass
class SweepExport:
    template: object  # the Export of the template (xosc, xodr, side file)
    distribution_path: Path
    form: str  # "deterministic" or "value sets"
    note: str
    runs: int


def varied_params(plan: ScenarioPlan) -> list[str]:
    """The parameters the sweep varies, in declaration order."""
    varied = axis_params(plan) | ({p.name for p in sampled_params(plan)} if plan.sweep.sampler else set())
    return [p.name for p in plan.params if p.name in varied]


def export_sweep(plan: ScenarioPlan, out_dir: str | Path, stem: str) -> SweepExport:
    out = Path(out_dir)
    stream = SweepStream(plan)
    first = next(iter(stream), None)
    if first is None:
        raise ExportError("the sweep has no run to export")
    names = varied_params(plan)
    if not names:
        raise ExportError("the sweep varies no parameter: export one run without --sweep")
    template = export_run(first, out, stem)
    # The template's OpenSCENARIO holds the numbers of one run (export_run): the scenario
    # with its parameters goes into its side file, where `addtc import` reads it back.
    side = json.loads(template.sidecar_path.read_text())
    side[PARAMETRIC_KEY] = plan.model_copy(update={"sweep": SweepPlan()}).model_dump(mode="json")
    template.sidecar_path.write_text(json.dumps(side, indent=2) + "\n")
    sw = plan.sweep
    root = ET.Element("OpenSCENARIO")
    ET.SubElement(root, "FileHeader", revMajor="1", revMinor=str(OSC_MINOR),
                  date=creation_date().isoformat(timespec="seconds"),
                  description=f"{plan.name}: the sweep's parameter values", author="addt-dsl")
    pvd = ET.SubElement(root, "ParameterValueDistribution")
    ET.SubElement(pvd, "ScenarioFile", filepath=template.xosc_path.name)
    det = ET.SubElement(pvd, "Deterministic")
    if sw.sampler is None and sw.repeat == 1 and not plan.assumptions:
        form = "deterministic"
        runs = len(stream)
        note = (f"grid: {runs} run(s) as {len(sw.grid)} DistributionSet(s)"
                + (f" and {len(sw.cases)} ValueSetDistribution(s)" if sw.cases else "") + ", multiplied")
        for axis in sw.grid:
            single = ET.SubElement(det, "DeterministicSingleParameterDistribution", parameterName=axis.param)
            dset = ET.SubElement(single, "DistributionSet")
            for v in axis.values:
                ET.SubElement(dset, "Element", value=repr(float(v)))
        for axis in sw.cases:
            vsd = ET.SubElement(ET.SubElement(det, "DeterministicMultiParameterDistribution"), "ValueSetDistribution")
            for row in axis.rows:
                pvs = ET.SubElement(vsd, "ParameterValueSet")
                for n, v in zip(axis.params, row):
                    ET.SubElement(pvs, "ParameterAssignment", parameterRef=n, value=repr(float(v)))
    else:
        form = "value sets"
        why = ", ".join(w for w, on in ((f"a {sw.sampler.kind} sampler" if sw.sampler else "", sw.sampler),
                                        (f"repeat {sw.repeat}", sw.repeat != 1),
                                        ("assumptions that skip cells", plan.assumptions and not sw.sampler),
                                        ("assumptions that reject draws", plan.assumptions and sw.sampler)) if on)
        vsd = ET.SubElement(ET.SubElement(det, "DeterministicMultiParameterDistribution"), "ValueSetDistribution")
        runs, size = 0, 0
        for spec in stream:
            pvs = ET.SubElement(vsd, "ParameterValueSet")
            for n in names:
                value = repr(float(spec.params[n]))
                ET.SubElement(pvs, "ParameterAssignment", parameterRef=n, value=value)
                size += len(n) + len(value) + 60
            runs += 1
            if size > MAX_XML_BYTES:
                raise ExportError(f"the sweep's value sets would be more than {MAX_XML_BYTES:,} bytes, more than "
                                  "an import reads: export fewer runs (`--limit` is not applied here)")
        note = (f"{why}: the {runs} run(s) as concrete parameter value sets (one ValueSetDistribution); "
                "OpenSCENARIO's Stochastic would draw other values with the player's generator")
    text = xml_text(root)
    path = out / f"{stem}.variation.xosc"
    path.write_text(text)
    return SweepExport(template, path, form, note, runs)
