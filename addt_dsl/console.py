"""Compiling a file with its diagnostics shown, as every `addtc` command does (cli, search
commands and studies sit above this and import it; it imports only the compiler and the
diagnostics). Exit codes are in addt_dsl/errors.py."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from addt_dsl.compiler import CompileResult, compile_file
from addt_dsl.compiler.overrides import parse_override
from addt_dsl.diagnostics import render_json, render_text
from addt_dsl.limits import DEFAULT, Limits


def compile_and_report(path: str, fmt: str = "text", limits: Limits = DEFAULT,
                       stack: Sequence[str] = (), root: str | None = None) -> CompileResult:
    """Compile `path` (with `--stack KEY=VALUE` settings, includes and maps read from under
    `root`, `--root`); its diagnostics go to stderr (as JSON on stdout with `fmt="json"`)."""
    result = compile_file(path, limits, stack, root)
    if result.diagnostics:
        text = render_json(result.diagnostics) if fmt == "json" else render_text(result.diagnostics, result.sources)
        print(text, file=sys.stderr if fmt != "json" else sys.stdout)
    return result


def _stack_setting(text: str) -> str:
    try:
        parse_override(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def stack_option(parser: argparse.ArgumentParser) -> None:
    """`--stack KEY=VALUE` (repeatable): a setting of the ego's stack for every run, as if
    the file said it (addt_dsl/compiler/overrides.py)."""
    parser.add_argument("--stack", action="append", default=[], type=_stack_setting, metavar="KEY=VALUE",
                        help="set a setting of the ego's stack, as if the file said it, e.g. "
                             "--stack perception=ground_truth (repeatable)")
