"""A scenario asks for a feature whose package is not installed (E0601).

Stacks declare which of their settings need a package outside the core install
(`required_modules(settings) -> {setting: module}`, e.g. `perception learned` → torch).
Checked with `importlib.util.find_spec` (through `addt_dsl.extras`), so compiling never
imports torch; without the check the run would fail inside a worker with an ImportError.
"""

from __future__ import annotations

from addt_dsl import extras
from addt_dsl.compiler import ast
from addt_dsl.diagnostics import Span
from addt_dsl.registry import STACKS


def check_optional_deps(ctx) -> None:
    """After the rules: reads the actors' lowered stack settings, reports at their source."""
    for name, actor in ctx.actors.items():
        if actor.stack is None:
            continue
        needs = getattr(STACKS.get(actor.stack.name), "required_modules", None)
        if needs is None:
            continue
        words = {k: v for k, v in actor.stack.settings.items() if isinstance(v, str)}
        for key, module in sorted(needs(words).items()):
            if not extras.missing(module):
                continue
            extra = extras.EXTRAS[module]
            ctx.sink.error("E0601", f"`{key} {words[key]}` needs {module}, which is not installed",
                           _setting_span(ctx.actors_ast.get(name), key, actor),
                           f"add the `{extra.name}` extra: {extra.install}",
                           "the core install runs ground-truth and camera perception without it",
                           label=f"needs the `{extra.name}` extra")


def _setting_span(decl: ast.ActorDecl | None, key: str, actor) -> Span | None:
    """The `key VALUE` setting of the actor's stack clause, else the clause, else the actor."""
    if decl is None:
        return None
    for clause in decl.clauses:
        if clause.keyword == "stack" and clause.name == actor.stack.name:
            setting = next((s for s in (*clause.settings, *clause.block) if s.key == key), None)
            return setting.span if setting is not None else clause.span
    return decl.span
