"""The latency model: measured trend and jitter, seeded sampling, explicit target factors."""

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.stack.calibrate import LEVELS, fit, jitter
from addt_dsl.stack.latency import (MODEL_PATH, NODES, Jitter, LatencyModel, at, crossing, e2e_ms,
                                    e2e_quantile_ms, load_models, target_names)

DATA = json.loads(MODEL_PATH.read_text())


def _draws(model: LatencyModel, seed: int, k: int, objects: int = 10) -> list[float]:
    rng = np.random.default_rng(seed)
    return [model.sample(objects, rng) for _ in range(k)]


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 300), st.sampled_from(NODES),
       st.lists(st.integers(0, 400), min_size=1, max_size=5))
def test_jitter_drawn_in_blocks_gives_a_call_of_the_generator_each(seed, n, node, counts):
    """`Jitter` (ratios of 64 uniforms in one kernel call) against `LatencyModel.sample` with
    one `random()` each, bit for bit, object counts varying draw to draw."""
    model = load_models()[node]
    one_by_one = np.random.default_rng(seed)
    blocked = Jitter(model, np.random.default_rng(seed))
    for k in range(n):
        objects = counts[k % len(counts)]
        assert blocked.sample(objects) == model.sample(objects, one_by_one)


@pytest.mark.parametrize("compiled", [True, False])
def test_ratios_of_gives_ratio_bits_at_the_table_levels_and_between(compiled):
    """The kernel against `ratio` at every stored level (equal to one: the step between two
    pieces), just below and above each, random points and the last level's flat top."""
    from addt_dsl import kernel
    model = load_models()["tracker"]
    lv = np.array(model.levels)
    u = np.concatenate([lv, np.nextafter(lv, -1.0), np.nextafter(lv, 2.0),
                        np.random.default_rng(3).random(2000), [0.0, 0.99999999999]])
    u = u[(u >= 0.0) & (u < 1.0)]
    if compiled:
        got = model.ratios_of(u)
    else:
        with kernel.interpreted():
            got = model.ratios_of(u)
    want = [model.ratio(float(x)) for x in u]
    assert [v.hex() for v in got.tolist()] == [v.hex() for v in want]


@pytest.mark.parametrize("node", NODES)
def test_sampling_repeats_with_the_seed_and_differs_across_seeds(node):
    model = load_models()[node]
    assert _draws(model, 7, 200) == _draws(model, 7, 200)
    assert _draws(model, 7, 200) != _draws(model, 8, 200)


@pytest.mark.parametrize("node", NODES)
def test_draws_follow_the_stored_quantile_table(node):
    """The CDF of many draws (fixed seed) at each stored quantile is that quantile's level,
    within 5 binomial standard errors (distribution-free); flat stretches of the table
    (equal ratios at two levels) hold the probability between them as an atom."""
    model = load_models()[node]
    k = 200_000
    ratios = model.ratios_at(np.random.default_rng(2024).random(k))
    levels, table = model.levels, model.ratios
    for i, (p, r) in enumerate(zip(levels, table)):
        if 0.0 < p < levels[-1] and table[i - 1] < r < table[i + 1]:
            cdf = float(np.mean(ratios <= r))
            assert abs(cdf - p) <= 5 * math.sqrt(p * (1 - p) / k) + 1e-9, (p, r, cdf)
    assert ratios.min() >= table[0] and ratios.max() <= table[-1]
    # The top 0.1 % sits at the last stored quantile (p99.9), as documented.
    assert np.mean(ratios == table[-1]) == pytest.approx(1 - levels[-1], abs=5 * math.sqrt(1e-3 / k) + 1e-4)
    # The scalar path draws from the same inverse CDF as the vectorised one.
    u = np.random.default_rng(5).random(500)
    assert np.allclose([model.ratio(float(v)) for v in u], model.ratios_at(u), rtol=1e-12, atol=0)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(0.1, 50.0), min_size=3, max_size=12, unique=True), st.floats(0.0, 1.0, exclude_max=True))
def test_inverse_cdf_interpolates_between_stored_quantiles(values, u):
    table = tuple(sorted(values))
    levels = tuple(np.linspace(0.0, 0.999, len(table)))
    m = LatencyModel(0.001, 0.0, levels, table)
    r = m.ratio(u)
    assert table[0] <= r <= table[-1]
    i = int(np.searchsorted(levels, u, side="right"))
    if i < len(levels):
        assert table[i - 1] <= r <= table[i]


def test_shipped_model_is_measured_data_with_hand_written_targets():
    assert tuple(DATA["jitter_levels"]) == LEVELS
    assert set(DATA["nodes"]) == set(NODES)
    for node, v in DATA["nodes"].items():
        r = v["jitter_ratios"]
        assert len(r) == len(LEVELS) and all(a <= b for a, b in zip(r, r[1:])), node
        assert r[LEVELS.index(0.5)] == pytest.approx(1.0, abs=0.05), node  # ratios to group medians
        assert v["base_s"] > 0 and v["per_object_s"] >= 0 and v["calls"] >= 100
    assert DATA["targets"]["host"]["cpu_scale"] == DATA["targets"]["host"]["accelerator_scale"] == 1.0
    for name, t in DATA["targets"].items():
        if name != "host":  # every factor carries its source or says it is an assumption
            assert t["cpu_scale_source"] and t["accelerator_scale_source"]
    assert target_names() == tuple(DATA["targets"])
    cal = DATA["calibration"]
    assert {"host", "loadavg", "repeats", "date"} <= set(cal)


def test_targets_scale_the_host_costs_by_their_stated_factors():
    host, xavier = load_models("host"), load_models("xavier")
    t = DATA["targets"]["xavier"]
    assert xavier["perception"].base_s == pytest.approx(host["perception"].base_s * t["accelerator_scale"])
    for node in NODES:
        assert xavier[node].per_object_s == pytest.approx(host[node].per_object_s * t["cpu_scale"])
        assert xavier[node].ratios == host[node].ratios  # jitter is relative: carried over as measured
    for node in ("tracker", "planner", "control"):
        assert xavier[node].base_s == pytest.approx(host[node].base_s * t["cpu_scale"])


def test_e2e_waits_for_the_next_step_at_each_hand_over():
    lat = {"perception": 0.0331, "tracker": 0.0001, "planner": 0.0064, "control": 0.0004}
    # Objects delivered at 40 ms, tracks at 50 ms; plan out 6.4 ms later; control 0.4 ms.
    assert math.isclose(e2e_ms(lat, 0.01), 56.8)


def _toy(per_object_s: float) -> dict[str, LatencyModel]:
    levels, table = (0.0, 0.5, 0.9, 0.999), (0.8, 1.0, 1.5, 3.0)
    return {n: LatencyModel(0.002, per_object_s if n != "control" else 0.0, levels, table) for n in NODES}


def test_e2e_quantiles_grow_with_probability_and_object_count():
    models = _toy(2e-4)
    median = e2e_ms(at(models, 50), 0.01)
    p50, p99 = (e2e_quantile_ms(models, 50, p, 0.01) for p in (0.5, 0.99))
    assert p50 <= p99 and median <= p99
    assert [e2e_quantile_ms(models, n, 0.99, 0.01) for n in (0, 50, 100)] == \
        sorted(e2e_quantile_ms(models, n, 0.99, 0.01) for n in (0, 50, 100))


def test_crossing_is_the_first_count_over_the_limit():
    models = _toy(2e-4)
    linear = next(n for n in range(2000) if e2e_ms(at(models, n), 0.01) > 100.0)
    assert crossing(models, 100.0, 0.01) == linear
    p99 = crossing(models, 100.0, 0.01, 0.99)
    assert p99 < linear  # the tail breaks the budget with fewer objects than the median
    assert e2e_quantile_ms(models, p99, 0.99, 0.01) > 100.0 >= e2e_quantile_ms(models, p99 - 1, 0.99, 0.01)
    assert crossing(_toy(0.0), 100.0, 0.01, max_objects=100) is None


def test_fit_uses_the_zero_object_cost_as_base_and_finds_pairwise_work():
    base, per, sq = fit([(0, 1.0), (10, 2.0), (20, 5.0)])  # super-linear, as association is
    assert base == 1.0 and sq > 0 and per >= 0
    base, per, sq = fit([(n, 2e-3 + 3e-6 * n + 8e-8 * n * n) for n in (0, 5, 20, 100, 400)])
    assert (base, per, sq) == (pytest.approx(2e-3), pytest.approx(3e-6), pytest.approx(8e-8))
    assert fit([(n, 1e-3 + 2e-6 * n) for n in (0, 10, 60)])[1:] == (pytest.approx(2e-6), pytest.approx(0.0, abs=1e-15))
    assert fit([(0, 1.0), (10, 2.0)]) == (1.0, 0.1, 0.0)  # two counts: a line


def test_jitter_is_relative_to_each_group_median():
    groups = [(0, [1.0, 2.0, 3.0]), (10, [10.0, 20.0, 30.0])]
    ratios, count = jitter(groups, levels=(0.0, 0.5, 1.0))
    assert count == 6 and ratios == [0.5, 1.0, 1.5]


def test_models_parsed_once_per_file_version(tmp_path, monkeypatch):
    """`load_models` parses a file once (it cost ~7 ms a run) and again when it changes."""
    import json
    import os

    from addt_dsl.stack import latency

    path = tmp_path / "model.json"
    data = latency.read()
    path.write_text(json.dumps(data))
    reads = []
    real_read = latency.read
    monkeypatch.setattr(latency, "read", lambda p=latency.MODEL_PATH: reads.append(p) or real_read(p))
    first = latency.load_models("host", path)
    assert latency.load_models("host", path) == first and len(reads) == 1
    assert first == latency.load_models("host", data=data)  # the same models as from the data
    data["nodes"]["planner"]["base_s"] = 2.0 * data["nodes"]["planner"]["base_s"]
    path.write_text(json.dumps(data))
    os.utime(path, ns=(1, 1))  # another version even where the clock's resolution is coarse
    changed = latency.load_models("host", path)
    assert len(reads) == 2 and changed["planner"].base_s == 2.0 * first["planner"].base_s
