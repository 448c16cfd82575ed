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
from dataclasses import dataclass, field
from pathlib import Path

from addt_dsl import expr as E
from addt_dsl.atomic import write_text
from addt_dsl.expr import eval_param_expr, params_used
from addt_dsl.interop.openscenario.xml import MAX_XML_BYTES
from addt_dsl.interop.xodr_export import ExportError, xml_text
from addt_dsl.interop.xosc_export import OSC_MINOR, creation_date, export_run
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
    referenced: list[str] = field(default_factory=list)  # Init attributes that now read parameters


# Init attributes that may read the parameters: (element path under <Private>, attribute, plan field).
INIT_PLACES = (("PrivateAction/TeleportAction/Position/LanePosition", "s", "s"),
               ("PrivateAction/TeleportAction/Position/LanePosition", "offset", "offset"),
               ("PrivateAction/TeleportAction/Position/LanePosition", "laneId", "lane"),
               ("PrivateAction/LongitudinalAction/SpeedAction/SpeedActionTarget/AbsoluteTargetSpeed", "value", "speed"))


def osc_expression(e) -> str | None:
    """An expression over parameters in OpenSCENARIO's `${...}` syntax (numbers, `$name`,
    + - * /, negation); None for anything else (signals, functions)."""
    if isinstance(e, E.Num):
        return repr(float(e.value))
    if isinstance(e, E.Param):
        return f"${e.name}"
    if isinstance(e, E.Unary) and e.op == "neg":
        inner = osc_expression(e.arg)
        return None if inner is None else f"-({inner})"
    if isinstance(e, E.Binary) and e.op in ("+", "-", "*", "/"):
        left, right = osc_expression(e.left), osc_expression(e.right)
        return None if left is None or right is None else f"({left} {e.op} {right})"
    return None


def _reference_parameters(xosc_path: Path, plan: ScenarioPlan, params: dict[str, float]) -> list[str]:
    """Where an actor's start (lane position, speed) depends on declared parameters, the
    template reads them (`$gap`, `${(10.0 + $gap)}`) instead of the first run's number, so
    that another player varies the starts too. Only where the number written is the
    expression's value for that run (the exporter wrote it from that expression and
    nothing else), so a convention of the exporter is never undone."""
    tree = ET.parse(xosc_path)
    root = tree.getroot()
    declared = {d.get("name") for d in root.iterfind("ParameterDeclarations/ParameterDeclaration")}
    actors = {a.name: a for a in plan.actors()}
    done = []
    for private in root.iterfind("Storyboard/Init/Actions/Private"):
        actor = actors.get(private.get("entityRef", ""))
        if actor is None:
            continue
        for path, attr, field_name in INIT_PLACES:
            el = private.find(path)
            expr = getattr(actor, field_name)
            if el is None or expr is None or el.get(attr) is None or isinstance(expr, E.Num):
                continue
            if not params_used(expr) or not params_used(expr) <= declared:
                continue
            if field_name == "lane":  # a lane id is a string: a parameter alone, not arithmetic
                text = f"${expr.name}" if isinstance(expr, E.Param) else None
            else:
                inner = osc_expression(expr)
                text = None if inner is None else (inner if isinstance(expr, E.Param) else "${" + inner + "}")
            try:
                matches = float(el.get(attr)) == float(eval_param_expr(expr, params))
            except (ValueError, ArithmeticError):
                matches = False
            if text is not None and matches:
                el.set(attr, text)
                done.append(f"{actor.name}: {el.tag} {attr}={text}")
    if done:
        write_text(xosc_path, xml_text(root))
    return done


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
    referenced = _reference_parameters(template.xosc_path, plan, first.params)
    # The template's OpenSCENARIO holds the numbers of one run (export_run): the scenario
    # with its parameters goes into its side file, where `addtc import` reads it back.
    side = json.loads(template.sidecar_path.read_text())
    side[PARAMETRIC_KEY] = plan.model_copy(update={"sweep": SweepPlan()}).model_dump(mode="json")
    write_text(template.sidecar_path, json.dumps(side, indent=2) + "\n")
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
    write_text(path, text)
    return SweepExport(template, path, form, note, runs, referenced)
