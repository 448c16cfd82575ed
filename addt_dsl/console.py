"""Compiling a file with its diagnostics shown, as every `addtc` command does (cli, search
commands and studies sit above this and import it; it imports only the compiler and the
diagnostics). Exit codes are in addt_dsl/errors.py."""

from __future__ import annotations

import sys

from addt_dsl.compiler import CompileResult, compile_file
from addt_dsl.diagnostics import render_json, render_text
from addt_dsl.limits import DEFAULT, Limits


def compile_and_report(path: str, fmt: str = "text", limits: Limits = DEFAULT) -> CompileResult:
    """Compile `path`; its diagnostics go to stderr (as JSON on stdout with `fmt="json"`)."""
    result = compile_file(path, limits)
    if result.diagnostics:
        text = render_json(result.diagnostics) if fmt == "json" else render_text(result.diagnostics, result.sources)
        print(text, file=sys.stderr if fmt != "json" else sys.stdout)
    return result
