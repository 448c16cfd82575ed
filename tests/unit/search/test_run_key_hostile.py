"""`addtc shrink --run-key SPEC.json` (and `--store`) read a RunSpec that met no compiler.
Before a run of it, it meets the compiler's checks and limits (printer.check_spec): a hostile
one is exit 2 with the compiler's diagnostic, and nothing is simulated. Before this, a spec
of 5000 agents simulated for minutes and one with a duration of 1e308 s, a step of 0, a
negative seed or a NaN parameter ended in 'internal error' (exit 3) after simulating."""

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl import cli
from addt_dsl import search as search_module
from addt_dsl.compiler import compile_file
from addt_dsl.errors import EXIT_USAGE
from addt_dsl.plan import RunSpec
from addt_dsl.printer import check_spec
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES

SPEC = expand(compile_file(EXAMPLES / "lead_brake.addt").plan).specs[0]
BASE = json.loads(SPEC.model_dump_json())


def _edit(path, value):
    data = json.loads(json.dumps(BASE))
    *parents, last = path
    node = data
    for key in parents:
        node = node[key]
    node[last] = value(node[last]) if callable(value) else value
    return data


HOSTILE = {
    "agents_5000": (("plan", "agents"), lambda agents: agents * 5000, "E0701"),
    "duration_1e308": (("plan", "duration_s"), 1e308, "E0301"),
    "duration_negative": (("plan", "duration_s"), -5.0, "E0301"),
    "step_zero": (("plan", "step_s"), 0.0, "E0301"),
    "seed_negative": (("seed",), -1, "E0301"),
    "seed_huge": (("seed",), 10**30, "E0301"),
    "param_nan": (("params", "lead_speed"), math.nan, "NaN has no surface syntax"),
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_a_hostile_run_key_is_exit_2_and_nothing_runs(name, tmp_path, capsys, monkeypatch):
    path, value, words = HOSTILE[name]
    spec_json = tmp_path / "spec.json"
    spec_json.write_text(json.dumps(_edit(path, value)))

    def no_simulation(*args, **kwargs):
        raise AssertionError("a hostile RunSpec reached the shrinker")

    monkeypatch.setattr(search_module, "Shrinker", no_simulation)
    code = cli.main(["shrink", "--run-key", str(spec_json), "--out", str(tmp_path / "out"), "--no-animation"])
    err = capsys.readouterr().err
    assert code == EXIT_USAGE, err
    assert err.startswith(f"error: the run in {spec_json} is not one a scenario can state") and words in err, err
    assert "Traceback" not in err and "internal error" not in err


def test_the_nominal_run_passes_the_check():
    check_spec(SPEC)


def _leaves(node, path=()):
    """Paths of the numeric leaves of a JSON tree."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _leaves(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _leaves(v, (*path, i))
    elif isinstance(node, (int, float)) and not isinstance(node, bool):
        yield path


LEAVES = sorted(_leaves(BASE), key=str)
NUMBERS = st.sampled_from([0, -1, 1e308, -1e308, 1e-300, 10**30, 2**63, math.inf, -math.inf, math.nan, 0.5, 7])


@settings(max_examples=30, deadline=None)
@given(path=st.sampled_from(LEAVES), value=NUMBERS)
def test_any_number_anywhere_is_accepted_or_a_value_error(path, value):
    """Fuzz: one number of the RunSpec replaced: the check passes or says why (ValueError);
    never another exception (the CLI would print 'internal error')."""
    data = _edit(path, value)
    try:
        spec = RunSpec.model_validate(data)
    except ValueError:
        return  # refused when read (pydantic): `cannot read a RunSpec from ...`, exit 2
    try:
        check_spec(spec)
    except ValueError:
        pass
