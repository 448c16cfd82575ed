"""Signals derived from a trace: the ones that need the run's past."""

import numpy as np
import pytest

from addt_dsl.registry import SIGNALS
from addt_dsl.runtime.trace import ActorTrack


def _track(x, y):
    n = len(x)
    zeros = np.zeros(n)
    return ActorTrack("ego", 4.5, 1.9, np.asarray(x, float), np.asarray(y, float), *[zeros] * 9)


class _Trace:
    def __init__(self, track):
        self.actors = {"ego": track}


def test_travelled_sums_the_path_not_the_displacement():
    # Out 3 m east, 4 m north, and back to the start: 14 m travelled, 0 m away.
    track = _track([0, 3, 3, 3, 0], [0, 0, 4, 0, 0])
    got = SIGNALS.get("travelled").compute(_Trace(track), ("ego",))
    assert got == pytest.approx([0, 3, 7, 11, 14])


def test_signals_of_the_past_are_marked_so_that_triggers_refuse_them():
    assert SIGNALS.get("travelled").history and SIGNALS.get("jerk").history
    assert not SIGNALS.get("speed").history and not SIGNALS.get("gap").history
