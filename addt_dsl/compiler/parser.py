"""Source text → AST. Syntax errors become diagnostics, never tracebacks.

One grammar (`grammar/addt.lark`, LALR(1), contextual lexer), two stages: lark parses
with `builder.Builder` as its transformer (the AST is built while parsing) and
`recovery.Recovery` as its error handler (every broken statement reported, panic mode).

Speed: a file is first run through `lalr_driver.Driver`, a tight loop over the
same lark tables and callbacks that gives up at the first syntax error; only then does
lark parse it again with recovery, so diagnostics are exactly lark's. The built parser is
cached on disk (lark's `cache`, keyed by the grammar text, lark and Python versions):
building it takes longer than compiling a hundred files.
"""

from __future__ import annotations

import functools
import hashlib
import os
import sys
import threading
from pathlib import Path

import lark as lark_module

from lark import Lark, Token, Tree
from lark.exceptions import UnexpectedInput

from addt_dsl.compiler import ast
from addt_dsl.compiler.builder import MAX_EXPR_DEPTH, Builder
from addt_dsl.compiler.lalr_driver import Driver, NotParsed
from addt_dsl.compiler.recovery import MAX_SOURCE_BYTES, Recovery, check_source, report_syntax_error
from addt_dsl.diagnostics import DiagnosticSink, Span
from addt_dsl.lru import LruCache

GRAMMAR_PATH = Path(__file__).resolve().parent.parent / "grammar" / "addt.lark"


CACHE_ENV = "ADDT_GRAMMAR_CACHE"  # a directory for the built parser; "off" builds it every time


def grammar_cache_dir() -> Path | None:
    """Where built parsers are kept: $ADDT_GRAMMAR_CACHE, else $XDG_CACHE_HOME/addt-dsl or
    ~/.cache/addt-dsl; None when turned off."""
    chosen = os.environ.get(CACHE_ENV)
    if chosen is not None:
        return None if chosen.strip().lower() in ("", "off", "0", "no") else Path(chosen)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "addt-dsl"


def grammar_cache_file(start: str, directory: Path) -> Path:
    """The cache file of the parser for `start`: its name holds a digest of everything the
    built parser depends on (grammar text, lark and Python versions), so a changed grammar
    or an upgraded lark never loads a stale parser (lark checks the same digest inside)."""
    text = GRAMMAR_PATH.read_text(encoding="utf-8")
    key = f"{text}\0{start}\0{lark_module.__version__}\0{sys.version_info[:2]}"
    return directory / f"grammar-{start}-{hashlib.sha256(key.encode()).hexdigest()[:24]}.lark"


def _build(start: str, builder: Builder) -> Lark:
    """The LALR parser of the grammar from `start`, loaded from the on-disk cache when there
    (written under a private name, then renamed: a reader never sees half a file)."""
    options = dict(parser="lalr", lexer="contextual", start=start,
                   transformer=_Callbacks(builder.callbacks()), maybe_placeholders=False)
    directory = grammar_cache_dir()
    if directory is not None:
        final = grammar_cache_file(start, directory)
        if final.is_file():
            return Lark.open(str(GRAMMAR_PATH), cache=str(final), **options)
        try:
            directory.mkdir(parents=True, exist_ok=True)
            tmp = final.with_name(f"{final.name}.{os.getpid()}.{threading.get_ident()}.tmp")
            with open(tmp, "wb"):  # writable? (lark would only log a failed write)
                pass
        except OSError:
            return Lark.open(str(GRAMMAR_PATH), **options)
        try:
            lark = Lark.open(str(GRAMMAR_PATH), cache=str(tmp), **options)
            os.replace(tmp, final)
            return lark
        finally:
            if tmp.exists():
                tmp.unlink()
    return Lark.open(str(GRAMMAR_PATH), **options)


@functools.lru_cache(maxsize=1)
def _parser() -> tuple[Lark, Builder, Driver]:
    """The parser, built once per process (a check of many files reuses it), with the
    AST builders called as it reduces: no parse tree is built or walked."""
    builder = Builder()
    lark = _build("start", builder)
    return lark, builder, Driver(lark)


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


INCLUDE_CACHE_SIZE = 64  # parsed files kept per process
_INCLUDED: LruCache[tuple[str, bytes, int], ast.SourceFile] = LruCache(INCLUDE_CACHE_SIZE)


def parse_included(data: bytes, path: str, sink: DiagnosticSink,
                   max_bytes: int = MAX_SOURCE_BYTES) -> ast.SourceFile | None:
    """`parse_source` for an included file, remembering clean parses within the process: a
    suite's files include the same shared definitions, which are then parsed once per
    `addtc check`/sweep, not once per file. The key is the file's content (a digest of its
    bytes: the caller reads the file every time, so an edited file is parsed again), the
    name its spans carry and the size limit; the AST is frozen, so sharing it is safe. A
    parse that reported anything is not kept (its diagnostics are reported every time)."""
    key = (path, hashlib.sha256(data.encode("utf-8") if isinstance(data, str) else data).digest(), max_bytes)
    tree = _INCLUDED.get(key)
    if tree is not None:
        return tree
    before = len(sink.items)
    tree = parse_source(data, path, sink, max_bytes)
    if tree is not None and len(sink.items) == before:
        _INCLUDED.put(key, tree)
    return tree


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
def _expression_parser() -> tuple[Lark, Builder, None]:
    """A parser of the same grammar started at its `expr` rule (with its own builder)."""
    builder = Builder()
    return _build("expr", builder), builder, None


def _parse(parser: tuple[Lark, Builder, Driver | None], text: str, path: str, sink: DiagnosticSink, recover: bool):
    lark, builder, driver = parser
    with _PARSE_LOCK:
        builder.path = path
        builder.reset()
        if driver is not None:
            try:
                result = driver.parse(text)
            except (NotParsed, RecursionError):
                builder.reset()  # lark parses it again, reporting the errors
            else:
                too_deep = builder.too_deep
                builder.reset()
                return _deep_enough(result, too_deep, sink)
    return _parse_lark(lark, builder, text, path, sink, recover)


def _deep_enough(result, too_deep, sink: DiagnosticSink):
    if too_deep is not None:
        sink.error("E0004", f"expression is too long or nested too deeply (limit {MAX_EXPR_DEPTH} operators)",
                   too_deep.span, "split it with parameters or simplify it")
        return None
    return result


def _parse_lark(lark: Lark, builder: Builder, text: str, path: str, sink: DiagnosticSink, recover: bool):
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
    return _deep_enough(result, too_deep, sink)


def parse_file(path: Path, sink: DiagnosticSink, display: str | None = None) -> tuple[ast.SourceFile | None, str]:
    name = display or str(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        sink.error("E0401", f"cannot read {name}: {exc.strerror or exc}", None)
        return None, ""
    text = data.decode("utf-8", errors="replace")
    return parse_source(data, name, sink), text


__all__ = ["GRAMMAR_PATH", "MAX_SOURCE_BYTES", "grammar", "parse_expression", "parse_file", "parse_included",
           "parse_source"]
