"""No input makes the compiler raise: it returns diagnostics, always.

Hypothesis feeds the compiler binary data, arbitrary text, soups of the language's own
tokens and mutations of real scenarios (deleted, duplicated, swapped and spliced
fragments), semantic faults planted in valid scenarios (temporal constraints, hostile
numbers, hostile include paths) and hostile OpenDRIVE maps. Every result must be a
`CompileResult`, every diagnostic must render, no diagnostic may be an internal compiler
error (E0900), and a plan that compiles must serialise and expand. Budget: FUZZ (conftest;
ADDT_FUZZ_EXAMPLES for longer runs).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from tests.unit.compiler.conftest import CASES_DIR, FUZZ, REPO
from hypothesis import example, given
from hypothesis import strategies as st

from addt_dsl.compiler import CompileResult, compile_source
from addt_dsl.diagnostics import CODES, render_json, render_text
from addt_dsl.plan import ScenarioPlan

SEEDS = [p.read_text() for p in sorted((REPO / "examples").glob("*.addt"))] + \
        [p.read_text() for p in sorted(CASES_DIR.glob("*.addt"))]
assert SEEDS

# The vocabulary of the language: keywords, punctuation, literals, units, names.
TOKENS = (
    "scenario", "road", "param", "assume", "keep", "ego", "agent", "faults", "expect", "sweep",
    "include", "import", "behavior", "sensor", "stack", "set", "when", "then", "at", "after",
    "for", "during", "from", "within", "sequence", "parallel", "ahead", "behind", "of", "lane",
    "left", "right", "no", "with", "stay", "in", "reach", "goal", "min", "max", "to", "hard", "warn",
    "always", "eventually", "until", "implies", "and", "or", "not", "true", "false", "grid",
    "random", "halton", "lhs", "repeat", "seed", "max_rejections", "dist", "normal", "uniform",
    "choice", "car", "truck", "pedestrian", "cyclist", "cruise", "brake", "cut_in", "lane_change",
    "lidar", "drop", "bitflip", "spike", "bev", "collision", "ttc", "jerk", "latency", "gap",
    "speed", "duration", "step", "length", "line", "arc", "spiral", "lanes", "width", "x", "lead",
    "{", "}", "[", "]", "(", ")", ",", ":", ".", "=", "==", "<", "<=", ">", ">=", "!=", "+", "-",
    "*", "/", "\n", "\n", "\n", " ", "  ", "#c\n", '"text"', '"', "\\\n",
    "0", "1", "-1", "2.5", "1e3", ".5", "1e999", "m", "s", "ms", "m/s", "km/h", "Hz", "deg", "%",
    "m/s^2", "1/m", "/m", "kph",
)


def check(source) -> CompileResult:
    result = compile_source(source, "fuzz.addt", base_dir=CASES_DIR)
    assert isinstance(result, CompileResult)
    codes = {d.code for d in result.diagnostics}
    assert "E0900" not in codes, render_text(result.diagnostics, result.sources)
    assert codes <= set(CODES), codes - set(CODES)
    render_text(result.diagnostics, result.sources)
    json.loads(render_json(result.diagnostics))
    if result.ok:
        text = result.plan.model_dump_json()
        assert ScenarioPlan.model_validate_json(text) == result.plan
        _expand_small(result.plan)
    else:
        assert any(d.is_error for d in result.diagnostics)
    return result


def _expand_small(plan) -> None:
    from addt_dsl.sweep import UnsatisfiableAssumptions, expand

    sweep = plan.sweep
    size = sweep.repeat * (sweep.sampler.count if sweep.sampler else 1)
    for axis in sweep.grid:
        size *= len(axis.values)
    if size <= 200:
        try:
            expand(plan)
        except UnsatisfiableAssumptions:
            pass


@FUZZ
@given(st.binary(max_size=2000))
@example(b"\xff\xfe\x00s\x00c")
@example(b"\x00")
@example("scenario é {".encode("utf-16"))
def test_binary(data):
    check(data)


@FUZZ
@given(st.text(max_size=2000))
@example("\ud800")
@example("scenario x {\u2028}")
def test_text(text):
    check(text)


@FUZZ
@given(st.lists(st.sampled_from(TOKENS), max_size=300).map(" ".join))
def test_token_soup(text):
    check(text)


@st.composite
def mutated(draw):
    """A real scenario with a few random edits at token or line granularity."""
    text = draw(st.sampled_from(SEEDS))
    for _ in range(draw(st.integers(1, 6))):
        edit = draw(st.sampled_from(("delete", "duplicate", "insert", "swap_lines", "replace", "truncate")))
        n = len(text)
        i = draw(st.integers(0, n))
        j = draw(st.integers(i, min(n, i + 60)))
        if edit == "delete":
            text = text[:i] + text[j:]
        elif edit == "duplicate":
            text = text[:j] + text[i:j] + text[j:]
        elif edit == "insert":
            text = text[:i] + " " + draw(st.sampled_from(TOKENS)) + " " + text[i:]
        elif edit == "replace":
            words = list(re.finditer(r"\S+", text))
            if words:
                w = draw(st.sampled_from(words))
                text = text[:w.start()] + draw(st.sampled_from(TOKENS)) + text[w.end():]
        elif edit == "swap_lines":
            lines = text.split("\n")
            a = draw(st.integers(0, len(lines) - 1))
            b = draw(st.integers(0, len(lines) - 1))
            lines[a], lines[b] = lines[b], lines[a]
            text = "\n".join(lines)
        else:
            text = text[:i]
    return text


@FUZZ
@given(mutated())
def test_mutated_examples(text):
    check(text)


@FUZZ
@given(st.sampled_from(SEEDS), st.integers(0, 10_000), st.integers(0, 10_000))
def test_splices(text, i, j):
    """Half of one file followed by part of itself: blocks cut mid-way."""
    i, j = i % (len(text) + 1), j % (len(text) + 1)
    check(text[:i] + text[j:])


# ---------------------------------------------------------------- planted semantic faults

EXAMPLES = [p.read_text() for p in sorted((REPO / "examples").glob("*.addt"))]
HOSTILE_NUMBERS = ("1e999", "-1e999", "0 / 0", "1e308 * 10", "1e308", "-1e308", "0", "1e-320", "(1 / 0) - (1 / 0)")
HOSTILE_PATHS = ("x" * 300 + ".addt", "../outside.addt", "/etc/hostname", "/dev/zero", "a\x1b[2J.addt",
                 "./" * 2100 + "a.addt", "maps/../../x.addt", "nope/" * 50 + "x.addt")


@st.composite
def planted(draw):
    """A valid example with one semantic fault planted where a real file could have it:
    a temporal operator in a constraint, a hostile number in place of a literal or as a
    distribution's mean or sd, a hostile include path."""
    text = draw(st.sampled_from(EXAMPLES))
    lines = text.split("\n")
    fault = draw(st.sampled_from(("temporal_assume", "number", "dist", "include")))
    if fault == "temporal_assume":
        op = draw(st.sampled_from(("always ", "eventually ", "always during [0 s, 1 s] ", "eventually within 2 s ",
                                   "not always ", "")))
        tail = draw(st.sampled_from(("", " until true", " until 1 > 0")))
        at = draw(st.integers(1, len(lines) - 1))
        lines.insert(at, f"  {draw(st.sampled_from(('assume', 'keep')))} {op}1 > 0{tail}")
    elif fault == "number":
        numbers = [(i, m) for i, line in enumerate(lines) for m in re.finditer(r"(?<![\w.])\d+(\.\d+)?", line)]
        if numbers:
            i, m = draw(st.sampled_from(numbers))
            lines[i] = lines[i][:m.start()] + draw(st.sampled_from(HOSTILE_NUMBERS)) + lines[i][m.end():]
    elif fault == "dist":
        params = [i for i, line in enumerate(lines) if line.strip().startswith("param ") and " in [" in line]
        if params:
            i = draw(st.sampled_from(params))
            unit = draw(st.sampled_from(("m", "m/s", "%", "")))
            lines[i] += (f" dist normal mean {draw(st.sampled_from(HOSTILE_NUMBERS))} {unit} "
                         f"sd {draw(st.sampled_from(HOSTILE_NUMBERS))} {unit}")
    else:
        lines.insert(0, f'include "{draw(st.sampled_from(HOSTILE_PATHS))}"')
    return "\n".join(lines)


@FUZZ
@given(planted())
def test_planted_semantic_faults(text):
    check(text)


SANE_MAP_NUMBERS = ("0", "0", "1", "3.5", "3.5", "100", "500", "0.001", "-0.01", "0.5")
HOSTILE_MAP_NUMBERS = ("-1", "1e12", "-1e12", "1e308", "-1e308", "1e-300", "nan", "inf", "-inf", "1e10", "5e4", "4e4",
                       "12", "x", "")
GEOMETRY_TAGS = (
    '<line/>', '<arc curvature="{a}"/>', '<spiral curvStart="{a}" curvEnd="{b}"/>',
    '<poly3 a="{a}" b="{b}" c="{c}" d="{d}"/>',
    '<paramPoly3 aU="{a}" bU="{b}" cU="{c}" dU="{d}" aV="{d}" bV="{c}" cV="{b}" dV="{a}" pRange="normalized"/>',
)


@st.composite
def hostile_map(draw):
    """An OpenDRIVE road whose numbers are drawn from hostile values (non-finite, huge,
    tiny, malformed): road length, geometry kind and coefficients, lane widths, offsets,
    elevation."""
    hostile = draw(st.floats(0.0, 0.5))  # how often a number is hostile: some maps are sane enough to compile

    def pick(sane):
        return st.builds(lambda u, a, b: a if u < hostile else b, st.floats(0.0, 1.0),
                         st.sampled_from(HOSTILE_MAP_NUMBERS), st.sampled_from(sane))

    num, size = pick(SANE_MAP_NUMBERS), pick(("100", "500", "3.5", "2.75"))
    n_geom = draw(st.integers(1, 3))
    geoms = []
    for k in range(n_geom):
        tag = draw(st.sampled_from(GEOMETRY_TAGS)).format(a=draw(num), b=draw(num), c=draw(num), d=draw(num))
        geoms.append(f'<geometry s="{draw(size) if k else 0}" x="{draw(num)}" y="0" hdg="{draw(num)}" '
                     f'length="{draw(size)}">{tag}</geometry>')
    return f"""<?xml version="1.0"?>
<OpenDRIVE><header revMajor="1" revMinor="4"/>
<road name="" length="{draw(size)}" id="1" junction="-1">
<planView>{''.join(geoms)}</planView>
<elevationProfile><elevation s="0" a="{draw(num)}" b="{draw(num)}" c="0" d="0"/></elevationProfile>
<lanes><laneOffset s="0" a="{draw(num)}" b="0" c="0" d="0"/>
<laneSection s="0"><center><lane id="0" type="none"/></center>
<right><lane id="-1" type="driving">
<width sOffset="0" a="{draw(size)}" b="{draw(num)}" c="0" d="{draw(num)}"/></lane></right>
</laneSection></lanes></road></OpenDRIVE>
"""


@FUZZ
@given(hostile_map())
def test_hostile_maps(xodr):
    """A hostile map is refused at the import, or it compiles and every run can build its
    road (the runtime's sampling included) in bounded memory."""
    import tempfile

    from addt_dsl.runtime.fastroad import FastRoad
    from addt_dsl.road.roadspec import build_network

    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "m.xodr").write_text(xodr)
        source = ('scenario s {\n  duration 5 s\n  road r import "m.xodr"\n'
                  '  ego car on r lane -1 at 1 m speed 1 m/s\n}\n')
        result = compile_source(source, str(Path(tmp) / "s.addt"), base_dir=tmp)
        codes = {d.code for d in result.diagnostics}
        assert "E0900" not in codes, render_text(result.diagnostics, result.sources)
        if result.ok:
            network = build_network(result.plan.roads)["r"]
            for road in network.roads.values():
                FastRoad(road)


# ---------------------------------------------------------------- extreme shapes

EXTREMES = {
    "deep_parens": "scenario x {\n expect {\n always " + "(" * 5000 + "true" + ")" * 5000 + "\n}\n}\n",
    "deep_not": "scenario x {\n expect {\n always " + "not " * 20000 + "true\n}\n}\n",
    "deep_neg": "scenario x {\n param p = " + "-" * 20000 + "1\n}\n",
    "long_sum": "scenario x {\n param p = " + " + ".join(["1"] * 20000) + "\n}\n",
    "long_and": "scenario x {\n expect {\n always " + " and ".join(["true"] * 20000) + "\n}\n}\n",
    "deep_always": "scenario x {\n expect {\n " + "always " * 20000 + "true\n}\n}\n",
    "deep_braces": "{" * 100_000,
    "many_lines": "scenario x {\n" + "  param p = 1\n" * 5_000 + "}\n",
    "many_errors": "scenario x {\n" + "  param = = =\n" * 5_000 + "}\n",
    "long_line": "scenario x { " + "a" * 500_000 + " }",
    "long_string": 'scenario x {\n description "' + "x" * 500_000 + '"\n}\n',
    "too_big": "#" * 1_500_000,
    "nul": "scenario x {\x00}",
    "huge_number": "scenario x {\n duration 1e400 s\n}\n",
    "nan_arith": "scenario x {\n duration 30 s\n road r { line length 1e308 m * 10 }\n}\n",
}


@pytest.mark.parametrize("name", sorted(EXTREMES))
def test_extreme_inputs(name):
    result = check(EXTREMES[name])
    assert not result.ok


@pytest.mark.parametrize("variant", ["crlf", "bom", "bom_bytes", "tabs"])
def test_encoding_variants_compile(variant):
    text = (REPO / "examples" / "overtake.addt").read_text()
    source = {"crlf": text.replace("\n", "\r\n"), "bom": "\ufeff" + text,
              "bom_bytes": b"\xef\xbb\xbf" + text.encode(), "tabs": text.replace("  ", "\t")}[variant]
    assert check(source).ok


def test_invalid_utf8_points_at_the_byte():
    result = check(b"scenario x {\n  description \"caf\xe9\"\n}\n")
    (diag,) = result.diagnostics
    assert (diag.code, diag.span.line, diag.span.col) == ("E0003", 2, 19)


def test_many_errors_are_capped():
    result = check(EXTREMES["many_errors"])
    assert 1 < len(result.diagnostics) <= 25
