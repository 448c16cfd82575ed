"""Grammar properties that keep the language usable as registries grow.

The lexer is contextual, but LALR state merging can make a keyword acceptable right after
a value in places where the grammar never takes it; a setting whose name is such a
keyword would then fail to parse. These tests write every registered setting in every
position where it can stand and require a clean parse.
"""

from __future__ import annotations

import pytest

from addt_dsl.compiler.rules import actors, header, params
from addt_dsl.compiler.parser import grammar, parse_source
from addt_dsl.diagnostics import DiagnosticSink
from addt_dsl.registry import BEHAVIORS, FAULTS, GEOMETRIES, SENSORS, STACKS


def _parses(source: str) -> list:
    sink = DiagnosticSink()
    parse_source(source, "t.addt", sink)
    return [d for d in sink.items if d.code in ("E0001", "E0002")]


def _pairs(names) -> str:
    # Each setting after a value that ends in a unit, and after a bare number.
    return " ".join(f"{n} 1 m" if i % 2 else f"{n} 2" for i, n in enumerate(names))


def _contexts():
    for cls in GEOMETRIES.classes():
        names = [p.name for p in cls.params]
        yield f"road {cls.keyword}", f"scenario x {{\n road r {{\n  {cls.keyword} {_pairs(names)}\n }}\n}}\n"
    for cls in BEHAVIORS.classes():
        names = [p.name for p in cls.params]
        yield f"behavior {cls.keyword}", (f"scenario x {{\n agent a car on r lane -1 at 1 m {{\n"
                                          f"  behavior {cls.keyword} {_pairs(names)}\n"
                                          f"  at 1 s behavior {cls.keyword} {_pairs(names)}\n }}\n}}\n")
    for table, kw in ((SENSORS, "sensor"), (STACKS, "stack")):
        for cls in table.classes():
            names = [p.name for p in cls.params]
            yield f"{kw} {cls.keyword}", (f"scenario x {{\n ego car on r lane -1 at 1 m {{\n"
                                          f"  {kw} {cls.keyword} {_pairs(names)}\n }}\n}}\n")
    for cls in FAULTS.classes():
        names = [p.name for p in cls.params] + ["seed"]
        yield f"fault {cls.keyword}", (f"scenario x {{\n faults {{\n  {cls.keyword} lidar {_pairs(names)}\n"
                                       f"  at 1 s for 1 s {cls.keyword} lidar {_pairs(names)}\n }}\n}}\n")
    actor = [p.name for p in actors.ACTOR_SETTINGS]
    yield "actor", f"scenario x {{\n agent a car {_pairs(actor)}\n ego car {_pairs(actor)} {{\n }}\n}}\n"
    yield "header", "scenario x {\n" + "".join(f" {n} 1 s\n" for n in header.HEADER) + "}\n"
    yield "param", f"param p = 1 m in [0 m, 2 m] {_pairs(params.PARAM_SETTINGS)}\n"
    yield "sampler", "sweep {\n random 10 seed 1\n lhs 2 seed 3\n}\n"
    yield "stay in lane", "expect {\n stay in lane tolerance 1 m\n}\n"


@pytest.mark.parametrize(("what", "source"), list(_contexts()), ids=[w for w, _ in _contexts()])
def test_every_registered_setting_parses_as_a_setting(what, source):
    assert _parses(source) == []


def test_grammar_is_built_once():
    assert grammar() is grammar()


def test_only_the_known_lalr_conflicts():
    """A window bound followed by its formula is the one ambiguity: `within t (x)` (a
    call, or a window then a parenthesis) and `within 5 s - x` (a difference, or a
    window then a negation). lark shifts: the bound takes the longest expression, so
    write `within 5 s (-x > 1)`. Any other conflict is a grammar bug."""
    import logging

    from lark import Lark, logger

    from addt_dsl.compiler.parser import GRAMMAR_PATH

    records = []

    class Collect(logging.Handler):
        def emit(self, record):
            records.append(record.getMessage())

    handler = Collect()
    logger.addHandler(handler)
    old = logger.level
    logger.setLevel(logging.DEBUG)
    try:
        Lark.open(str(GRAMMAR_PATH), parser="lalr", lexer="contextual", debug=True)
    finally:
        logger.removeHandler(handler)
        logger.setLevel(old)
    conflicts = {r.split("terminal ")[1].split(":")[0] for r in records if "conflict" in r.lower()}
    assert conflicts == {"LPAR", "MINUS"}, conflicts
