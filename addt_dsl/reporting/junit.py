"""JUnit XML for CI systems: one `<testcase>` per run.

A run whose oracles all held passes. A run where an oracle failed carries a `<failure>`
naming each failing oracle with its robustness and first violation time; a run the
executor had to stop (crashed, timeout, memory) carries an `<error>`. A violated `warn`
oracle is not a failure: it is a `warning.NAME` property and a line in `<system-out>`. The class name is
the scenario plus the sweep cell, so CI dashboards group repeats of one cell together.
Runs are streamed from the store, so the file can be written for any sweep size.
"""

from __future__ import annotations

import math
from pathlib import Path
from xml.etree import ElementTree as ET

from addt_dsl.errors import is_error_status
from addt_dsl.atomic import atomic_path
from addt_dsl.reporting.tables import fmt_number, fmt_param


def _cell_label(plan, cell: dict) -> str:
    return ",".join(f"{k}={fmt_param(plan, k, v).replace(' ', '')}" for k, v in sorted(cell.items()))


def _violation(v) -> str:
    when = f" first violated at t={v.first_violation_s:.2f} s" if v.first_violation_s is not None else ""
    return f"{v.name}: robustness {fmt_number(v.robustness)}{when}"


def failure_message(record) -> str:
    parts = [_violation(v) for v in record.verdicts if v.severity == "hard" and not v.passed]
    if record.status == "detected":
        parts.append(f"stack_health: {record.error.splitlines()[0] if record.error else 'detected'}")
    return "; ".join(parts)


def junit_tree(plan, records) -> ET.ElementTree:
    suite = ET.Element("testsuite", name=plan.name)
    props = ET.SubElement(suite, "properties")
    ET.SubElement(props, "property", name="source", value=plan.source_file)
    tests = failures = errors = 0
    total_time = 0.0
    for r in records:
        tests += 1
        total_time += r.wall_time_s
        classname = plan.name + (f"[{_cell_label(plan, r.cell)}]" if r.cell else "")
        case = ET.SubElement(suite, "testcase", classname=classname, name=r.run_id,
                             time=f"{r.wall_time_s:.3f}")
        cprops = ET.SubElement(case, "properties")
        ET.SubElement(cprops, "property", name="seed", value=str(r.seed))
        ET.SubElement(cprops, "property", name="key", value=r.key)
        for k, v in sorted(r.params.items()):
            ET.SubElement(cprops, "property", name=f"param.{k}", value=repr(v))
        for v in r.verdicts:
            rho = v.robustness
            ET.SubElement(cprops, "property", name=f"robustness.{v.name}",
                          value="inf" if math.isinf(rho) and rho > 0 else ("-inf" if math.isinf(rho) else repr(rho)))
        warned = set(r.warned_oracles)
        for v in r.verdicts:
            if v.name in warned:
                ET.SubElement(cprops, "property", name=f"warning.{v.name}", value=_violation(v))
        if warned:
            ET.SubElement(case, "system-out").text = "\n".join(
                f"warning: {_violation(v)}" for v in r.verdicts if v.name in warned)
        if is_error_status(r.status):
            errors += 1
            el = ET.SubElement(case, "error", type=r.status, message=(r.error.splitlines() or [r.status])[0])
            el.text = r.error
        elif not r.passed:
            failures += 1
            message = failure_message(r)
            el = ET.SubElement(case, "failure", type="oracle" if r.status == "ok" else r.status, message=message)
            el.text = "\n".join(message.split("; ")) + f"\nparams: {r.params}\nseed: {r.seed}"
    suite.set("tests", str(tests))
    suite.set("failures", str(failures))
    suite.set("errors", str(errors))
    suite.set("skipped", "0")
    suite.set("time", f"{total_time:.3f}")
    root = ET.Element("testsuites", tests=str(tests), failures=str(failures), errors=str(errors),
                      time=f"{total_time:.3f}")
    root.append(suite)
    return ET.ElementTree(root)


def merge_junit(trees: list[ET.ElementTree]) -> ET.ElementTree:
    """One <testsuites> holding every tree's <testsuite> (a suite of scenario files)."""
    root = ET.Element("testsuites")
    totals = {"tests": 0, "failures": 0, "errors": 0}
    time_s = 0.0
    for tree in trees:
        for suite in tree.getroot().findall("testsuite"):
            root.append(suite)
            for key in totals:
                totals[key] += int(suite.get(key, "0"))
            time_s += float(suite.get("time", "0"))
    for key, value in totals.items():
        root.set(key, str(value))
    root.set("time", f"{time_s:.3f}")
    return ET.ElementTree(root)


def write_tree(path: str | Path, tree: ET.ElementTree) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ET.indent(tree)
    with atomic_path(path) as tmp:
        tree.write(tmp, encoding="utf-8", xml_declaration=True)
    return path


def write_junit(path: str | Path, plan, records) -> Path:
    return write_tree(path, junit_tree(plan, records))
