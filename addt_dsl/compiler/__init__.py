"""The compiler: `.addt` source → checked AST → `ScenarioPlan`.

Pipeline: `parser.parse_source` (lark → AST with spans), include resolution (paths stay
inside the scenario's directory tree), `rules.RULES` in order (one module per rule), then
`lower.build_plan`.
Never imports pybullet or torch.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from addt_dsl import cost
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import Context
from addt_dsl.compiler.lower import build_plan, check_feasible
from addt_dsl.compiler.optional_deps import check_optional_deps
from addt_dsl.compiler.overrides import apply_stack_overrides
from addt_dsl.compiler.parser import parse_included, parse_source
from addt_dsl.confine import Refused, confine, shown
from addt_dsl.compiler.rules import run_rules
from addt_dsl.diagnostics import Diagnostic, DiagnosticSink, Span
from addt_dsl.limits import DEFAULT, Limits, beyond_message, how_to_raise
from addt_dsl.plan import ScenarioPlan

MAX_INCLUDE_DEPTH = 16
# Byte limits (one .addt file, all .addt text, one map, all reads) are fields of
# `addt_dsl.limits.Limits`, raised with `--max NAME=N`.


@dataclass
class CompileResult:
    plan: ScenarioPlan | None
    diagnostics: list[Diagnostic]
    sources: dict[str, str] = field(default_factory=dict)
    estimate: cost.CostEstimate | None = None  # what the sweep will cost (docs/limits.md)

    @property
    def ok(self) -> bool:
        return self.plan is not None and not any(d.is_error for d in self.diagnostics)


class _Loader:
    """Reads files for includes and road imports, confined to the root directory tree."""

    def __init__(self, root: Path, sink: DiagnosticSink, sources: dict[str, str], limits: Limits = DEFAULT):
        self.limits = limits
        self.root = root.resolve()
        self.shown_root = root
        self.sink = sink
        self.sources = sources
        self.included: set[Path] = set()  # each file is read and parsed at most once
        self.texts: dict[Path, tuple[str, str]] = {}  # imports read once per compilation
        self.bytes_read = 0
        self.addt_bytes = 0  # .addt text read so far (the main file and includes)

    def display(self, path: Path) -> str:
        """How diagnostics name a file: relative to the working directory, else to the
        scenario's directory as the user named it (never an absolute path the user did not type)."""
        try:
            return str(path.relative_to(Path.cwd().resolve()))
        except ValueError:
            inside = path.relative_to(self.root)
            # An absolute scenario path shows its files relative to the scenario's directory.
            return str(inside if self.shown_root.is_absolute() else self.shown_root / inside)

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
                self._too_large(relative, size, limit, span)
                return None
            with path.open("rb") as fh:
                data = _read_at_most(fh, limit)
        except OSError as exc:
            self.sink.error("E0401", f"cannot read '{shown(relative)}': {exc.strerror or exc}", span)
            return None
        if len(data) > limit:
            self._too_large(relative, len(data), limit, span)
            return None
        self.bytes_read += len(data)
        if self.bytes_read > self.limits.read_bytes:
            self.sink.error("E0701", beyond_message(f"the bytes read with '{shown(relative)}'", self.bytes_read,
                                                    "read_bytes", self.limits.read_bytes), span,
                            how_to_raise("read_bytes"))
            return None
        return data

    def _too_large(self, relative: str, size: int, limit: int, span: Span) -> None:
        name = "map_bytes" if limit == self.limits.map_bytes else "source_bytes"
        self.sink.error("E0701", beyond_message(f"the size of '{shown(relative)}' [bytes]", size, name, limit), span,
                        how_to_raise(name))

    def count_addt(self, size: int, relative: str, span: Span) -> bool:
        """Add an .addt file's bytes to the compilation's total; False (reported) beyond it."""
        self.addt_bytes += size
        if self.addt_bytes <= self.limits.included_bytes:
            return True
        self.sink.error("E0701", beyond_message(f"the .addt text with '{shown(relative)}' [bytes]", self.addt_bytes,
                                                "included_bytes", self.limits.included_bytes), span,
                        how_to_raise("included_bytes"))
        return False

    def read_text(self, relative: str, base: Path, span: Span) -> tuple[str, str] | None:
        path = self.resolve(relative, base, span)
        if path is None:
            return None
        if path not in self.texts:
            data = self.read_bytes(path, relative, span, self.limits.map_bytes)
            if data is None:
                return None
            self.texts[path] = (self.display(path), data.decode("utf-8", errors="replace"))
        return self.texts[path]


def _read_at_most(fh, limit: int) -> bytes:
    """Up to limit + 1 bytes, in chunks: `read(n)` allocates n bytes up front, and a limit
    raised to 1e12 must not ask for a terabyte; a size from `stat` can lie (/proc)."""
    chunks, total = [], 0
    while total <= limit:
        chunk = fh.read(min(1 << 20, limit + 1 - total))
        if not chunk:
            break
        chunks.append(chunk)
        total += len(chunk)
    return b"".join(chunks)


def compile_file(path: str | Path, limits: Limits = DEFAULT, stack: Sequence[str] = (),
                 root: str | Path | None = None) -> CompileResult:
    """Compile one file; `stack` holds `KEY=VALUE` settings for the ego's stack (`--stack`).
    Includes and maps are read from under `root` (`--root`; default: the file's directory),
    which must hold the file."""
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
            data = _read_at_most(fh, limits.source_bytes)
    except OSError as exc:
        sink.error("E0401", f"cannot read {display}: {exc.strerror or exc}", None)
        return CompileResult(None, sink.items, sources)
    if size > limits.source_bytes or len(data) > limits.source_bytes:
        sink.error("E0003", beyond_message("the source's size [bytes]", max(size, len(data)), "source_bytes",
                                           limits.source_bytes), Span.point(display, 1, 1),
                   how_to_raise("source_bytes"))
        return CompileResult(None, sink.items, sources)
    if root is not None and not _holds(Path(root), path.parent):
        sink.error("E0402", f"{display} is not under the root directory {root}", None,
                   "--root names a directory that holds the scenario (a repository's root)")
        return CompileResult(None, sink.items, sources)
    return _compile_guarded(data, display, path.parent, sink, sources, limits, stack, root)


def _holds(root: Path, directory: Path) -> bool:
    try:
        directory.resolve().relative_to(root.resolve())
        return root.is_dir()
    except (ValueError, OSError):
        return False


def compile_source(text: str | bytes, path: str = "<input>", base_dir: str | Path = ".",
                   limits: Limits = DEFAULT, stack: Sequence[str] = (),
                   root: str | Path | None = None) -> CompileResult:
    sink = DiagnosticSink()
    if root is not None and not _holds(Path(root), Path(base_dir)):
        root = None  # a root that does not hold the file confines nothing more than its directory
    return _compile_guarded(text, path, Path(base_dir), sink, {}, limits, stack, root)


def _compile_guarded(data, display: str, base_dir: Path, sink: DiagnosticSink,
                     sources: dict[str, str], limits: Limits = DEFAULT, stack: Sequence[str] = (),
                     root: str | Path | None = None) -> CompileResult:
    """Compile; a bug in the compiler is an "internal compiler error" diagnostic (E0900),
    never a traceback. The fuzz tests assert that E0900 never appears."""
    try:
        return _compile(data, display, base_dir, sink, sources, limits, stack, root)
    except RecursionError:
        sink.error("E0004", "source nested too deeply", Span.point(display, 1, 1))
    except Exception as exc:  # noqa: BLE001 - the last line of defence, reported as data
        sink.error("E0900", f"internal compiler error: {type(exc).__name__}: {exc}", Span.point(display, 1, 1),
                   "this is a bug in addtc; please report it with the input file")
    return CompileResult(None, sink.items, sources)


def _compile(data, display: str, base_dir: Path, sink: DiagnosticSink, sources: dict[str, str],
             limits: Limits, stack: Sequence[str] = (), root: str | Path | None = None) -> CompileResult:
    sources[display] = data.decode("utf-8", errors="replace") if isinstance(data, bytes) else data
    tree = parse_source(data, display, sink, max_bytes=limits.source_bytes)
    if tree is None:
        return CompileResult(None, sink.items, sources)
    loader = _Loader(Path(root) if root is not None else base_dir, sink, sources, limits)
    loader.addt_bytes = len(data)
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
    scenario = apply_stack_overrides(scenario, stack, sink, sources)  # `--stack KEY=VALUE`
    if not _within_count_limits(scenario, sink, limits):
        return CompileResult(None, sink.items, sources)  # checking it all would cost what the limit bounds

    def read_file(relative: str, span: Span):
        got = loader.read_text(relative, base_dir, span)
        return got

    ctx = Context(scenario, sink, str(base_dir), display, read_file=read_file, sources=sources, limits=limits)
    run_rules(ctx)
    check_optional_deps(ctx)
    if sink.has_errors:
        return CompileResult(None, sink.items, sources)
    plan = build_plan(ctx)
    estimate = cost.estimate(plan)
    refused = cost.over_thresholds(estimate, limits)
    if refused:  # one diagnostic: the first threshold passed, the others as notes
        (name, message), others = refused[0], refused[1:]
        sweeps = ctx.blocks("sweep")
        sweep_wide = name in ("runs", "sim_seconds", "agent_steps", "wall_seconds")
        span = sweeps[0].span if sweeps and sweep_wide else scenario.span
        sink.error("E0701", message, span, *(f"also {m}" for _, m in others), *estimate.lines(),
                   how_to_raise(name))
    if refused or not check_feasible(plan, ctx):
        return CompileResult(None, sink.items, sources, estimate)
    return CompileResult(plan, sink.items, sources, estimate)


def _within_count_limits(scenario: ast.Scenario, sink: DiagnosticSink, limits: Limits) -> bool:
    """Agents, parameters, oracles and faults within their limits (E0701 at the first one beyond)."""
    found = {"agents": [], "params": [], "oracles": [], "faults": []}
    for d in scenario.definitions:
        if isinstance(d, ast.ActorDecl) and not d.is_ego:
            found["agents"].append(d)
        elif isinstance(d, ast.ParamDecl):
            found["params"].append(d)
        elif isinstance(d, ast.Block) and d.kind in ("expect", "faults"):
            found["oracles" if d.kind == "expect" else "faults"].extend(d.items)
    ok = True
    for name, items in found.items():
        limit = getattr(limits, name)
        if len(items) > limit:
            ok = False
            sink.error("E0701", beyond_message(f"the scenario's number of {name}", len(items), name, limit),
                       items[int(limit)].span, how_to_raise(name))
    return ok


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
        data = loader.read_bytes(path, inc.path, inc.span, loader.limits.source_bytes)
        if data is None or not loader.count_addt(len(data), inc.path, inc.span):
            continue
        loader.sources[display] = data.decode("utf-8", errors="replace")
        tree = parse_included(data, display, loader.sink, max_bytes=loader.limits.source_bytes)
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
