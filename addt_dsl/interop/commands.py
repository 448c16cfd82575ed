"""`addtc export` and `addtc import`: OpenSCENARIO in and out (docs/openscenario.md).

    addtc export FILE.addt [--run ID | --params NAME=VALUE ... | --sweep] --to DIR
    addtc import FILE.xosc [-o FILE.addt] [--root DIR] [--maps DIR] [--format text|json]

Exit codes follow `addtc` (addt_dsl/errors.py): 0 done, 2 usage or scenario error (an
import with errors writes nothing).
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from addt_dsl import units
from addt_dsl.console import compile_and_report
from addt_dsl.diagnostics import render_json, render_text
from addt_dsl.errors import EXIT_OK, EXIT_USAGE, UsageError
from addt_dsl.printer import check_spec, format_quantity
from addt_dsl.sweep import expand, make_spec

# The translators (scenariogeneration, the road reader) load in the commands that use them,
# as cli.py does for its commands: `addtc check` does not pay for them.

_VALUE = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(\S*)\s*$")


def add_commands(sub) -> None:
    exp = sub.add_parser("export", help="write one run as OpenSCENARIO XML + OpenDRIVE (+ a side file)")
    exp.add_argument("file")
    pick = exp.add_mutually_exclusive_group()
    pick.add_argument("--run", metavar="ID", help="the sweep's run to export (e.g. c002-r000; default: the first)")
    pick.add_argument("--params", nargs="+", metavar="NAME=VALUE", default=[],
                      help="parameter values (with units, e.g. gap=30m); the others keep their defaults")
    pick.add_argument("--sweep", action="store_true",
                      help="the whole sweep: the first run as the template and a ParameterValueDistribution "
                           "(FILE.variation.xosc) of the sweep's parameter values")
    exp.add_argument("--to", required=True, metavar="DIR", help="output directory")
    exp.set_defaults(func=cmd_export)
    imp = sub.add_parser("import", help="translate an OpenSCENARIO file into .addt")
    imp.add_argument("file")
    imp.add_argument("-o", "--output", metavar="FILE.addt", help="write here (default: print)")
    imp.add_argument("--root", metavar="DIR", help="files (road, catalogs) may come from here and below "
                                                   "(default: the scenario's directory)")
    imp.add_argument("--maps", metavar="DIR", action="append", default=[],
                     help="a folder of road networks (repeatable): a <LogicFile> named without a folder, or "
                          "without .xodr as CARLA names its towns (Town01), is also looked for here")
    imp.add_argument("--format", choices=("text", "json"), default="text")
    imp.add_argument("--lenient", action="store_true",
                     help="import what translates and leave out the rest with a warning (W0801); by default an "
                          "element that is not translated is an error (E0803): the run would not be the scenario")
    imp.add_argument("--ego", choices=("stack", "scripted"), default="stack",
                     help="stack (default): the stack under test drives the ego and actions on it are not "
                          "translated; scripted: the ego follows every action the file gives it")
    imp.set_defaults(func=cmd_import)


def _param_values(plan, items: list[str]) -> dict[str, float]:
    dims = {p.name: units.dim_from_name(p.dimension) for p in plan.params}
    params = {p.name: p for p in plan.params}
    values = plan.nominal_params()
    for item in items:
        name, _, text = item.partition("=")
        match = _VALUE.match(text)
        if name not in dims:
            raise UsageError(f"--params: no parameter '{name}' (parameters: {', '.join(dims) or 'none'})")
        if not match:
            raise UsageError(f"--params {item}: give NAME=VALUE, e.g. {name}=3.5m")
        try:
            value, dim = units.to_si(float(match.group(1)), match.group(2) or None)
        except units.UnknownUnit:
            raise UsageError(f"--params {item}: unknown unit '{match.group(2)}'") from None
        if match.group(2) and dim != dims[name]:
            raise UsageError(f"--params {item}: {name} is a {units.dim_name(dims[name])}")
        # The compiler checked every value that depends on a parameter over its range (or
        # choices) only: a value beyond them would export what no run of the scenario can be.
        p = params[name]
        shown = [format_quantity(v, dims[name]) for v in (p.choices or (p.low, p.high)) if v is not None]
        if p.choices and value not in p.choices:
            raise UsageError(f"--params {item}: {name} is one of {', '.join(shown)}")
        if p.low is not None and p.high is not None and not p.low <= value <= p.high:
            raise UsageError(f"--params {item}: outside {name}'s range [{', '.join(shown)}]")
        if p.integer and value != int(value):
            raise UsageError(f"--params {item}: {name} is a whole number")
        values[name] = value
    return values


def cmd_export(args) -> int:
    from addt_dsl.interop.xodr_export import ExportError
    from addt_dsl.interop.xosc_export import export_run

    result = compile_and_report(args.file, "text")
    if not result.ok:
        return EXIT_USAGE
    plan = result.plan
    if args.sweep:
        return _export_sweep(plan, args)
    specs = expand(plan).specs
    if args.run:
        spec = next((s for s in specs if s.run_id == args.run), None)
        if spec is None:
            raise UsageError(f"no run '{args.run}' in the sweep (runs: {specs[0].run_id} .. {specs[-1].run_id})")
    elif args.params:
        spec = make_spec(plan, _param_values(plan, args.params), specs[0].seed, run_id="params")
        try:  # a parameter without a range: its value meets the compiler's checks here
            check_spec(spec)
        except ValueError as exc:
            raise UsageError(f"--params {' '.join(args.params)}: not a run the scenario can state: {exc}") from None
    else:
        spec = specs[0]
    try:
        done = export_run(spec, args.to, Path(args.file).stem)
    except ExportError as exc:
        raise UsageError(f"cannot export {args.file}: {exc}") from None
    print(f"exported run {spec.run_id or '-'} of {args.file}:")
    for path in (done.xosc_path, done.xodr_path, done.sidecar_path):
        print(f"  {path}")
    print(f"carried in {done.sidecar_path.name} (no OpenSCENARIO equivalent): {len(done.carried)}")
    for line in done.carried:
        print(f"  - {line}")
    return EXIT_OK


def _export_sweep(plan, args) -> int:
    from addt_dsl.interop.openscenario.distribution_export import export_sweep
    from addt_dsl.interop.xodr_export import ExportError

    try:
        done = export_sweep(plan, args.to, Path(args.file).stem)
    except ExportError as exc:
        raise UsageError(f"cannot export the sweep of {args.file}: {exc}") from None
    t = done.template
    print(f"exported the sweep of {args.file} ({done.runs} run(s), {done.form}):")
    for path in (done.distribution_path, t.xosc_path, t.xodr_path, t.sidecar_path):
        print(f"  {path}")
    print(f"note: {done.note}")
    print(f"the template's starts that read the parameters: {len(done.referenced)} (other uses hold the first run's "
          "numbers; addtc import reads the parameters from the side file)")
    for line in done.referenced:
        print(f"  - {line}")
    print(f"carried in {t.sidecar_path.name} (no OpenSCENARIO equivalent): {len(t.carried)}")
    for line in t.carried:
        print(f"  - {line}")
    return EXIT_OK


def cmd_import(args) -> int:
    from addt_dsl.interop.openscenario.importer import import_xosc

    got = import_xosc(args.file, args.root, args.maps, lenient=args.lenient, ego=args.ego)
    if args.format == "json":
        print(render_json(got.diagnostics))
    elif got.diagnostics:
        print(render_text(got.diagnostics, got.sources), file=sys.stderr, end="")
    if got.text is None:
        return EXIT_USAGE
    if args.output:
        from addt_dsl.atomic import write_text

        out = Path(args.output)
        write_text(out, got.text)
        for name, body in got.side_files.items():
            write_text(out.parent / name, body)
        if args.format == "text":
            print(f"wrote {out}" + "".join(f", {out.parent / n}" for n in got.side_files))
    elif args.format == "text":
        print(got.text, end="")
    return EXIT_OK
