"""Source text → AST. Syntax errors become diagnostics, never tracebacks.

One grammar (`grammar/addt.lark`, LALR(1), contextual lexer), two stages: lark parses
with `builder.Builder` as its transformer (the AST is built while parsing) and
`recovery.Recovery` as its error handler (every broken statement reported, panic mode).
"""

from __future__ import annotations

import functools
import threading
from pathlib import Path

from lark import Lark, Token, Tree
from lark.exceptions import UnexpectedInput

from addt_dsl.compiler import ast
from addt_dsl.compiler.builder import MAX_EXPR_DEPTH, Builder
from addt_dsl.compiler.recovery import MAX_SOURCE_BYTES, Recovery, check_source, report_syntax_error
from addt_dsl.diagnostics import DiagnosticSink, Span

GRAMMAR_PATH = Path(__file__).resolve().parent.parent / "grammar" / "addt.lark"


@functools.lru_cache(maxsize=1)
def _parser() -> tuple[Lark, Builder]:
    """The parser, built once per process (a check of many files reuses it), with the
    AST builders called as it reduces: no parse tree is built or walked."""
    builder = Builder()
    lark = Lark.open(str(GRAMMAR_PATH), parser="lalr", lexer="contextual",
                     transformer=_Callbacks(builder.callbacks()), maybe_placeholders=False)
    return lark, builder


def grammar() -> Lark:
    return _parser()[0]


class _Callbacks:
    """What lark's `transformer=` option reads: one attribute per rule name."""

    def __init__(self, table: dict):
        self.__dict__.update(table)

    def __default__(self, data, children, meta):
        if data.startswith("_"):  # an inlined rule: lark splices its children into the parent
            return Tree(data, children)
        raise RuntimeError(f"no AST builder for grammar rule '{data}'")


_PARSE_LOCK = threading.Lock()  # the builder holds the current file name


def parse_source(data: bytes | str, path: str, sink: DiagnosticSink,
                 max_bytes: int = MAX_SOURCE_BYTES) -> ast.SourceFile | None:
    """Parse one file's contents; syntax errors go to `sink`; None if nothing usable.
    `max_bytes` is the `source_bytes` limit (addt_dsl/limits.py)."""
    text = check_source(data, path, sink, max_bytes)
    if text is None:
        return None
    if not text.endswith("\n"):
        text += "\n"
    return _parse(_parser(), text, path, sink, recover=True)


def parse_expression(text: str, path: str, sink: DiagnosticSink) -> ast.Expression | None:
    """Parse one expression or formula (the grammar's `expr` rule, e.g. an oracle given
    on its own); syntax errors go to `sink`; None if it does not parse."""
    text = check_source(text, path, sink)
    if text is None:
        return None
    parser = _expression_parser()
    result = _parse(parser, text, path, sink, recover=False)
    if isinstance(result, Token):  # `true` / `false`: lark reduced no rule
        result = parser[1].literal(result)
    return result


@functools.lru_cache(maxsize=1)
def _expression_parser() -> tuple[Lark, Builder]:
    """A parser of the same grammar started at its `expr` rule (with its own builder)."""
    builder = Builder()
    lark = Lark.open(str(GRAMMAR_PATH), parser="lalr", lexer="contextual", start="expr",
                     transformer=_Callbacks(builder.callbacks()), maybe_placeholders=False)
    return lark, builder


def _parse(parser: tuple[Lark, Builder], text: str, path: str, sink: DiagnosticSink, recover: bool):
    lark, builder = parser
    recovery = Recovery(lark, text, path, sink)
    with _PARSE_LOCK:
        builder.path = path
        builder.reset()
        try:
            result = lark.parse(text, on_error=recovery.on_error if recover else None)
        except UnexpectedInput as exc:
            if not recovery.failed:
                report_syntax_error(lark, exc, path, sink, text)
            return None
        except RecursionError:
            sink.error("E0004", "source nested too deeply", Span.point(path, 1, 1))
            return None
        too_deep = builder.too_deep
        builder.reset()
    if recovery.failed:
        return None
    if too_deep is not None:
        sink.error("E0004", f"expression is too long or nested too deeply (limit {MAX_EXPR_DEPTH} operators)",
                   too_deep.span, "split it with parameters or simplify it")
        return None
    return result


def parse_file(path: Path, sink: DiagnosticSink, display: str | None = None) -> tuple[ast.SourceFile | None, str]:
    name = display or str(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        sink.error("E0401", f"cannot read {name}: {exc.strerror or exc}", None)
        return None, ""
    text = data.decode("utf-8", errors="replace")
    return parse_source(data, name, sink), text


__all__ = ["GRAMMAR_PATH", "MAX_SOURCE_BYTES", "grammar", "parse_expression", "parse_file", "parse_source"]
