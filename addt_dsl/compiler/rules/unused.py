"""Parameters that no setting, constraint or oracle uses (W0001)."""

from __future__ import annotations

from addt_dsl.compiler.context import Context


def rule_unused(ctx: Context) -> None:
    checked = {p.name for p in ctx.params}  # a broken one is reported already (a set: linear time)
    for name, d in ctx.params_ast.items():
        if name in checked and name not in ctx.used_params:
            ctx.sink.warning("W0001", f"parameter '{name}' is never used", d.span,
                             "use it in a setting, a constraint or an oracle, or remove it")
