"""The stack's bus: delivery in (time, publish order); `due` says whether `deliver_until`
would return anything, without delivering (the stack's step skips its messages when not)."""

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.stack.bus import Bus

_ops = st.lists(st.one_of(
    st.tuples(st.just("publish"), st.sampled_from(["objects", "tracks", "plan"]),
              st.integers(0, 40).map(lambda k: 0.01 * k)),
    st.tuples(st.just("deliver"), st.integers(0, 40).map(lambda k: 0.01 * k + st_eps(k)))),
    max_size=60)


def st_eps(k: int) -> float:
    return (-1e-13, 0.0, 1e-13, 5e-12)[k % 4]  # around the 1e-12 tolerance


@settings(max_examples=200, deadline=None)
@given(_ops)
def test_due_is_whether_deliver_until_returns_messages(ops):
    bus, queued = Bus(), []  # queued: (deliver_s, seq, topic), the reference
    for seq, op in enumerate(ops):
        if op[0] == "publish":
            _, topic, at = op
            bus.publish(topic, seq, 0.0, at)
            queued.append((at, seq, topic))
        else:
            t = op[1]
            want = sorted(m for m in queued if m[0] <= t + 1e-12)
            assert bus.due(t) == bool(want)
            got = bus.deliver_until(t)
            assert [(m.deliver_s, m.data, m.topic) for m in got] == want
            queued = [m for m in queued if m[0] > t + 1e-12]
            assert not bus.due(t)
        assert bus.next_s == min((m[0] for m in queued), default=math.inf)
