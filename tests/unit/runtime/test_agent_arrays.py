"""The agents' state as arrays with a leading runs axis (`agent_arrays.AgentArrays`) and the
per-agent views (`AgentState`): moving agents into a batch's block keeps every value bit for
bit; a view reads and writes its own slot and nothing else; the padding and the masks say
which slots are agents; the lane-anchor counts and teleport masks move with the agents."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.runtime.agent_arrays import ACCEL, FIELDS, SCALE, AgentArrays, AgentState

finite_or_not = st.one_of(st.floats(allow_nan=False, width=64), st.sampled_from([math.nan, math.inf, -0.0]))


def agent(name: str, values, placed=False, anchor=None) -> AgentState:
    s, t, speed, accel, scale = values
    return AgentState(name, "r", s, t, speed, accel, 4.5, 1.8, -1, t, ground_scale=scale, placed=placed,
                      lane_anchor=anchor)


def same(a: float, b: float) -> bool:
    return np.float64(a).tobytes() == np.float64(b).tobytes()


@settings(max_examples=60, deadline=None)
@given(st.lists(st.lists(st.tuples(*[finite_or_not] * len(FIELDS), st.booleans(), st.booleans()), max_size=5),
                min_size=1, max_size=4))
def test_adopted_agents_keep_their_values_in_a_padded_block(runs):
    groups = [[agent(f"a{r}_{i}", row[:5], placed=row[5], anchor=(1, None, 0.0) if row[6] else None)
               for i, row in enumerate(rows)] for r, rows in enumerate(runs)]
    block = AgentArrays.adopt(groups)
    width = max(len(rows) for rows in runs)
    assert block.values.shape == (len(FIELDS), len(runs), width)
    assert block.valid.tolist() == [[i < len(rows) for i in range(width)] for rows in runs]
    for r, rows in enumerate(runs):
        assert block.anchored[r] == sum(row[6] for row in rows)
        for i, row in enumerate(rows):
            a = groups[r][i]
            assert all(same(getattr(a, f), v) for f, v in zip(FIELDS, row[:5]))
            assert all(same(block.values[j, r, i], v) for j, v in enumerate(row[:5]))
            assert a.placed is row[5] and block.placed[r, i] == row[5]
            assert block.flat[:, block.rows(r)[i]].tobytes() == block.values[:, r, i].tobytes()
    pad = ~block.valid  # padding: ground scale 1, the rest 0, never teleported
    assert (block.values[:SCALE][:, pad] == 0.0).all() and (block.values[SCALE][pad] == 1.0).all()
    assert not block.placed[pad].any()


def test_a_view_writes_its_own_slot_and_reads_what_the_phases_wrote():
    a, b, c = (agent(n, (10.0 * k, 1.0, 5.0, 0.0, 1.0)) for k, n in enumerate("abc"))
    block = AgentArrays.adopt([[a], [b, c]])
    before = block.values.copy()
    c.s += 2.5
    c.placed = True
    changed = np.argwhere(block.values != before).tolist()
    assert changed == [[0, 1, 1]] and block.placed.tolist() == [[False, False], [False, True]]
    block.flat[ACCEL, block.rows(1)] = (-1.5, 0.25)  # a phase writes the run's accelerations
    assert (b.accel, c.accel, a.accel) == (-1.5, 0.25, 0.0)
    assert type(b.accel) is float  # views give Python floats, as the attributes were


def test_lane_anchor_counts_follow_the_agents_into_a_new_block():
    a, b = agent("a", (0.0,) * 4 + (1.0,)), agent("b", (0.0,) * 4 + (1.0,), anchor=(2, None, 0.5))
    own = b._block
    assert own.anchored == [1]
    block = AgentArrays.adopt([[a], [b]])
    assert own.anchored == [0] and block.anchored == [0, 1]
    a.lane_anchor = (1, None, 0.0)
    a.lane_anchor = (1, "leg", 0.1)  # (replaced: counted once)
    b.lane_anchor = None
    assert block.anchored == [1, 0] and a.lane_anchor == (1, "leg", 0.1)
