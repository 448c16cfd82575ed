"""The semantic checks: one module per rule, run in the order of `RULES`.

Like sqlglot's optimizer rules, each rule is a plain function of the `Context` that
returns its product (a small dataclass whose fields are fields of the context: the
checked plan pieces it derives) or None; `run_rules` stores each product before the next
rule runs, so later rules read what earlier ones derived (names before uses).
Diagnostics go to the context's sink. Rules never stop at the first error: a broken
statement is reported and skipped, the rest is still checked.
"""

from __future__ import annotations

from addt_dsl.compiler.context import Context
from addt_dsl.compiler.rules.actors import rule_actors
from addt_dsl.compiler.rules.assumptions import rule_assumptions
from addt_dsl.compiler.rules.ending import rule_end
from addt_dsl.compiler.rules.environment import rule_environment
from addt_dsl.compiler.rules.faults import rule_faults
from addt_dsl.compiler.rules.goal import rule_goal_oracle
from addt_dsl.compiler.rules.header import rule_header
from addt_dsl.compiler.rules.lights import rule_lights
from addt_dsl.compiler.rules.names import rule_names
from addt_dsl.compiler.rules.oracles import rule_oracles
from addt_dsl.compiler.rules.params import rule_params
from addt_dsl.compiler.rules.roads import rule_roads
from addt_dsl.compiler.rules.sweep import rule_sweep
from addt_dsl.compiler.rules.unused import rule_unused
from addt_dsl.compiler.rules.variables import rule_variables

RULES = (
    rule_names,
    rule_header,
    rule_params,
    rule_sweep,  # right after the parameters: its grids widen their ranges for every later check
    rule_assumptions,  # and the constraints narrow them
    rule_roads,
    rule_actors,
    rule_lights,
    rule_faults,
    rule_environment,
    rule_variables,
    rule_oracles,
    rule_end,
    rule_goal_oracle,
    rule_unused,
)


def run_rules(ctx: Context) -> None:
    for rule in RULES:
        product = rule(ctx)
        if product is not None:
            ctx.absorb(product)


__all__ = ["RULES", "run_rules"]
