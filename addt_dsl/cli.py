"""`addtc`: compile, run and judge `.addt` scenarios.

    addtc FILE [--jobs N] [--out DIR]     compile and run the file's sweep, print verdicts
    addtc check FILE...                   compile only (diagnostics)
    addtc plan FILE                       print the ScenarioPlan as JSON
    addtc schema [--write PATH]           the plan's JSON schema
    addtc shrink FILE | --run-key JSON    shrink a failing run to a minimal replayable .addt file
    addtc falsify FILE [--budget-runs N]  search parameters and faults for failures

Exit codes: 0 every oracle held in every run, 1 some run failed, 2 compile/usage error.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from addt_dsl.diagnostics import render_json, render_text

EXIT_OK, EXIT_FAILED, EXIT_ERROR = 0, 1, 2
SUBCOMMANDS = ("run", "check", "plan", "schema", "shrink", "falsify")


def _compile(path: str, fmt: str):
    from addt_dsl.compiler import compile_file

    result = compile_file(path)
    if result.diagnostics:
        text = render_json(result.diagnostics) if fmt == "json" else render_text(result.diagnostics, result.sources)
        print(text, file=sys.stderr if fmt != "json" else sys.stdout)
    return result


def cmd_check(args) -> int:
    failed = False
    for path in args.files:
        result = _compile(path, args.format)
        failed |= not result.ok
        if result.ok and args.format != "json":
            print(f"ok: {path}")
    return EXIT_ERROR if failed else EXIT_OK


def cmd_plan(args) -> int:
    result = _compile(args.file, args.format)
    if not result.ok:
        return EXIT_ERROR
    print(result.plan.model_dump_json(indent=2))
    return EXIT_OK


def cmd_schema(args) -> int:
    from addt_dsl.plan import plan_json_schema

    text = json.dumps(plan_json_schema(), indent=2) + "\n"
    if args.write:
        Path(args.write).write_text(text)
        print(f"wrote {args.write}")
    else:
        print(text, end="")
    return EXIT_OK


def cmd_run(args) -> int:
    result = _compile(args.file, args.format)
    if not result.ok:
        return EXIT_ERROR
    from addt_dsl.sweep import UnsatisfiableAssumptions, expand

    try:
        expansion = expand(result.plan)
    except UnsatisfiableAssumptions as exc:
        print(f"error[E0501]: {exc}", file=sys.stderr)
        return EXIT_ERROR
    specs = expansion.specs
    if args.limit:
        specs = specs[: args.limit]
    from addt_dsl.report import print_verdicts, write_outputs
    from addt_dsl.runtime.executor import run_local

    results = _run_with_progress(specs, args.jobs, quiet=args.format == "json")
    if expansion.rejected:
        for text, n in expansion.rejected.most_common():
            print(f"note: assumption `{text}` rejected {n} candidate run(s)", file=sys.stderr)
    if args.out:
        write_outputs(Path(args.out), result.plan, results, expansion.rejected)
    print_verdicts(result.plan, results, fmt=args.format)
    return EXIT_OK if all(r.passed for r in results) else EXIT_FAILED


def _run_with_progress(specs, jobs: int, quiet: bool):
    from addt_dsl.runtime.executor import run_local

    if quiet or len(specs) < 4 or not sys.stderr.isatty():
        return run_local(specs, jobs)
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    with Progress("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
                  TimeRemainingColumn(), transient=True) as progress:
        task = progress.add_task("runs", total=len(specs))
        return run_local(specs, jobs, on_result=lambda r: progress.advance(task))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="addtc", description="Compile and run .addt driving scenarios.")
    sub = parser.add_subparsers(dest="command")
    run = sub.add_parser("run", help="compile and run a scenario (default)")
    run.add_argument("file")
    run.add_argument("--jobs", "-j", type=int, default=max(1, os.cpu_count() or 1))
    run.add_argument("--out", help="write summary.json and runs.csv here")
    run.add_argument("--limit", type=int, default=0, help="run only the first N runs of the sweep")
    run.add_argument("--format", choices=("text", "json"), default="text")
    run.set_defaults(func=cmd_run)
    check = sub.add_parser("check", help="compile only")
    check.add_argument("files", nargs="+")
    check.add_argument("--format", choices=("text", "json"), default="text")
    check.set_defaults(func=cmd_check)
    plan = sub.add_parser("plan", help="print the execution plan as JSON")
    plan.add_argument("file")
    plan.add_argument("--format", choices=("text", "json"), default="text")
    plan.set_defaults(func=cmd_plan)
    schema = sub.add_parser("schema", help="print or write the plan's JSON schema")
    schema.add_argument("--write", help="file to write")
    schema.set_defaults(func=cmd_schema)
    from addt_dsl.search.commands import add_commands

    add_commands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] not in SUBCOMMANDS and not argv[0].startswith("-"):
        argv.insert(0, "run")
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_ERROR
    try:
        return args.func(args)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
