"""The compiler: `.addt` source → checked AST → `ScenarioPlan`.

Pipeline: `parser.parse_source` (lark → AST with spans), include resolution (paths stay
inside the scenario's directory tree), `rules.RULES` in order (one module per rule), then
`lower.build_plan`.
Never imports pybullet or torch.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from addt_dsl.compiler import ast, parser
from addt_dsl.compiler.context import Context
from addt_dsl.compiler.lower import build_plan, check_feasible
from addt_dsl.compiler.optional_deps import check_optional_deps
from addt_dsl.compiler.parser import parse_source
from addt_dsl.confine import Refused, confine, shown
from addt_dsl.compiler.rules import run_rules
from addt_dsl.diagnostics import Diagnostic, DiagnosticSink, Span
from addt_dsl.plan import ScenarioPlan

MAX_INCLUDE_DEPTH = 16
MAX_INCLUDED_BYTES = parser.MAX_SOURCE_BYTES  # an .addt file, main or included
MAX_IMPORT_BYTES = 50_000_000  # an imported .xodr file
MAX_TOTAL_BYTES = 200_000_000  # everything one compilation may read


@dataclass
class CompileResult:
    plan: ScenarioPlan | None
    diagnostics: list[Diagnostic]
    sources: dict[str, str] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.plan is not None and not any(d.is_error for d in self.diagnostics)


class _Loader:
    """Reads files for includes and road imports, confined to the root directory tree."""

    def __init__(self, root: Path, sink: DiagnosticSink, sources: dict[str, str]):
        self.root = root.resolve()
        self.shown_root = root
        self.sink = sink
        self.sources = sources
        self.included: set[Path] = set()  # each file is read and parsed at most once
        self.texts: dict[Path, tuple[str, str]] = {}  # imports read once per compilation
        self.bytes_read = 0

    def display(self, path: Path) -> str:
        """How diagnostics name a file: relative to the working directory, else to the
        scenario's directory as the user named it (never an absolute path the user did not type)."""
        try:
            return str(path.relative_to(Path.cwd().resolve()))
        except ValueError:
            return str(self.shown_root / path.relative_to(self.root))

    def resolve(self, relative: str, base: Path, span: Span) -> Path | None:
        try:
            return confine(relative, base, self.root)
        except Refused as refused:
            self.sink.error(refused.code, refused.message, span, *([refused.note] if refused.note else []))
            return None

    def read_bytes(self, path: Path, relative: str, span: Span, limit: int) -> bytes | None:
        """Read a file after checking its size (a huge or endless file must not stall us)."""
        try:
            size = path.stat().st_size
            if size > limit:
                self.sink.error("E0401", f"'{shown(relative)}' is too large ({size} bytes; limit {limit})", span)
                return None
            with path.open("rb") as fh:
                data = fh.read(limit + 1)
        except OSError as exc:
            self.sink.error("E0401", f"cannot read '{shown(relative)}': {exc.strerror or exc}", span)
            return None
        if len(data) > limit:
            self.sink.error("E0401", f"'{shown(relative)}' is too large (limit {limit} bytes)", span)
            return None
        self.bytes_read += len(data)
        if self.bytes_read > MAX_TOTAL_BYTES:
            self.sink.error("E0401", f"reading '{shown(relative)}' exceeds the {MAX_TOTAL_BYTES} bytes one compilation "
                            "may read", span)
            return None
        return data

    def read_text(self, relative: str, base: Path, span: Span) -> tuple[str, str] | None:
        path = self.resolve(relative, base, span)
        if path is None:
            return None
        if path not in self.texts:
            data = self.read_bytes(path, relative, span, MAX_IMPORT_BYTES)
            if data is None:
                return None
            self.texts[path] = (self.display(path), data.decode("utf-8", errors="replace"))
        return self.texts[path]


def compile_file(path: str | Path) -> CompileResult:
    path = Path(path)
    sink = DiagnosticSink()
    sources: dict[str, str] = {}
    display = str(path)
    try:
        if not path.is_file():
            sink.error("E0401", f"cannot read {display}: " + ("it is a directory" if path.is_dir()
                                                               else "no such file"), None)
            return CompileResult(None, sink.items, sources)
        size = path.stat().st_size
        with path.open("rb") as fh:
            data = fh.read(MAX_INCLUDED_BYTES + 1)
    except OSError as exc:
        sink.error("E0401", f"cannot read {display}: {exc.strerror or exc}", None)
        return CompileResult(None, sink.items, sources)
    if size > MAX_INCLUDED_BYTES or len(data) > MAX_INCLUDED_BYTES:
        sink.error("E0003", f"source is too large ({size} bytes; limit {MAX_INCLUDED_BYTES})",
                   Span.point(display, 1, 1))
        return CompileResult(None, sink.items, sources)
    return _compile_guarded(data, display, path.parent, sink, sources)


def compile_source(text: str | bytes, path: str = "<input>", base_dir: str | Path = ".") -> CompileResult:
    sink = DiagnosticSink()
    return _compile_guarded(text, path, Path(base_dir), sink, {})


def _compile_guarded(data, display: str, base_dir: Path, sink: DiagnosticSink,
                     sources: dict[str, str]) -> CompileResult:
    """Compile; a bug in the compiler is an "internal compiler error" diagnostic (E0900),
    never a traceback. The fuzz tests assert that E0900 never appears."""
    try:
        return _compile(data, display, base_dir, sink, sources)
    except RecursionError:
        sink.error("E0004", "source nested too deeply", Span.point(display, 1, 1))
    except Exception as exc:  # noqa: BLE001 - the last line of defence, reported as data
        sink.error("E0900", f"internal compiler error: {type(exc).__name__}: {exc}", Span.point(display, 1, 1),
                   "this is a bug in addtc; please report it with the input file")
    return CompileResult(None, sink.items, sources)


def _compile(data, display: str, base_dir: Path, sink: DiagnosticSink, sources: dict[str, str]) -> CompileResult:
    sources[display] = data.decode("utf-8", errors="replace") if isinstance(data, bytes) else data
    tree = parse_source(data, display, sink)
    if tree is None:
        return CompileResult(None, sink.items, sources)
    loader = _Loader(base_dir, sink, sources)
    if len(tree.scenarios) != 1:
        if not tree.scenarios:
            sink.error("E0103", "no scenario in this file", Span.point(display, 1, 1),
                       "a runnable file declares `scenario NAME { ... }`")
        else:
            sink.error("E0102", "more than one scenario in one file", tree.scenarios[1].span)
        return CompileResult(None, sink.items, sources)
    scenario = tree.scenarios[0]
    included = _resolve_includes(tree.includes + scenario.includes, base_dir, loader, [display])
    scenario = dataclasses.replace(scenario, definitions=included + scenario.definitions)

    def read_file(relative: str, span: Span):
        got = loader.read_text(relative, base_dir, span)
        return got

    ctx = Context(scenario, sink, str(base_dir), display, read_file=read_file, sources=sources)
    run_rules(ctx)
    check_optional_deps(ctx)
    if sink.has_errors:
        return CompileResult(None, sink.items, sources)
    plan = build_plan(ctx)
    if not check_feasible(plan, ctx):
        return CompileResult(None, sink.items, sources)
    return CompileResult(plan, sink.items, sources)


def _resolve_includes(includes, base: Path, loader: _Loader, stack: list[str]) -> tuple:
    defs: list = []
    for inc in includes:
        if len(stack) > MAX_INCLUDE_DEPTH:
            loader.sink.error("E0401", "includes nested too deeply", inc.span)
            continue
        path = loader.resolve(inc.path, base, inc.span)
        if path is None:
            continue
        display = loader.display(path)
        if display in stack:
            loader.sink.error("E0108", f"including '{inc.path}' again makes an include cycle", inc.span,
                              "include chain: " + " → ".join([*stack, display]))
            continue
        if path in loader.included:
            continue  # included once already (a diamond): its definitions are in
        loader.included.add(path)
        data = loader.read_bytes(path, inc.path, inc.span, MAX_INCLUDED_BYTES)
        if data is None:
            continue
        loader.sources[display] = data.decode("utf-8", errors="replace")
        tree = parse_source(data, display, loader.sink)
        if tree is None:
            continue
        if tree.scenarios:
            loader.sink.error("E0204", f"'{inc.path}' declares a scenario; included files hold definitions only",
                              inc.span)
            continue
        defs.extend(_resolve_includes(tree.includes, path.parent, loader, [*stack, display]))
        defs.extend(tree.definitions)
    return tuple(defs)


__all__ = ["CompileResult", "compile_file", "compile_source", "ast"]
