"""Stack settings given on the command line: `addtc FILE --stack perception=ground_truth`.

Each `KEY=VALUE` replaces (or adds) one setting of the ego's `stack` clause before the
rules run, as if the file said it: the value is parsed as an `.addt` expression and
checked against the stack's settings table like any other, so a wrong key or value is a
diagnostic pointing into the command-line text, and everything that depends on the
setting (fault sites, required sensors, the learned detector's lidar warning) follows it.
The compiled plan carries the result, so runs, stores and printed counterexamples are
those of the overridden scenario. The paper suites use it for their ground-truth
screening variant (docs/paper-comparison.md).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from addt_dsl.compiler import ast
from addt_dsl.compiler.parser import parse_expression
from addt_dsl.diagnostics import DiagnosticSink, Span

# Where the diagnostics of an override point: the text `KEY=VALUE` as a source of its own.
DISPLAY = "--stack"


def parse_override(text: str) -> tuple[str, str]:
    """`perception=ground_truth` -> ("perception", "ground_truth"); ValueError if malformed."""
    key, sep, value = text.partition("=")
    key, value = key.strip(), value.strip()
    if not sep or not key.isidentifier() or not value:
        raise ValueError(f"--stack {text!r}: expected KEY=VALUE, e.g. --stack perception=ground_truth")
    return key, value


def apply_stack_overrides(scenario: ast.Scenario, overrides: Sequence[str], sink: DiagnosticSink,
                          sources: dict[str, str]) -> ast.Scenario:
    """`scenario` with each `KEY=VALUE` of `overrides` set in its ego's stack clause (a
    `stack bev` clause is added when the ego has none). Syntax errors go to `sink`."""
    if not overrides:
        return scenario
    settings: list[ast.Setting] = []
    for i, text in enumerate(overrides, start=1):
        display = DISPLAY if len(overrides) == 1 else f"{DISPLAY} #{i}"
        sources[display] = text
        try:
            key, _ = parse_override(text)
        except ValueError as exc:
            sink.error("E0001", str(exc), Span.point(display, 1, 1))
            continue
        # Blanks in place of `KEY=` keep the value's columns those of the command-line text.
        value = parse_expression(" " * (text.index("=") + 1) + text[text.index("=") + 1:], display, sink)
        if value is not None:
            key_span = Span(display, 1, 1, 1, len(key) + 1)
            settings.append(ast.Setting(Span(display, 1, 1, 1, len(text) + 1), key, key_span, value))
    egos = [d for d in scenario.definitions if isinstance(d, ast.ActorDecl) and d.is_ego]
    if not settings or not egos:
        if settings:
            sink.error("E0103", "--stack sets the ego's stack, but the scenario has no ego", scenario.span)
        return scenario
    ego = egos[0]
    keys = {s.key for s in settings}
    clauses, found = [], False
    for c in ego.clauses:
        if c.keyword == "stack" and not found:
            found = True
            by_key = {s.key: s for s in settings}  # in place where the file has the key, else appended
            given = {s.key for s in c.settings}
            replaced = tuple(by_key.get(s.key, s) for s in c.settings)
            c = dataclasses.replace(c, settings=replaced + tuple(s for s in settings if s.key not in given),
                                    block=tuple(s for s in c.block if s.key not in keys))
        clauses.append(c)
    if not found:
        clauses.append(ast.Clause(settings[0].span, "stack", "bev", settings[0].key_span, tuple(settings)))
    new_ego = dataclasses.replace(ego, clauses=tuple(clauses))
    definitions = tuple(new_ego if d is ego else d for d in scenario.definitions)
    return dataclasses.replace(scenario, definitions=definitions)
