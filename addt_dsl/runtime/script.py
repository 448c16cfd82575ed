"""Agent scripts: steps (`at`, `after`, `when`) composed in sequence or in parallel.

The compiler lowers an agent's steps to a tree of `TriggerPlan`/`GroupPlan`, bound for a
run into `BoundStep`/`BoundGroup` (runtime/bound.py); this module runs that tree in
simulated time. A step is armed, fires when its start conditions hold (a `when`
condition with `for D` must have held at every step for D)
(starting its behaviour and arming its group), and is done once it fired and its group
is done. A sequence arms each step when the previous one is done (fired: not when its
behaviour ended, which `when ended(X)` waits for); a parallel group arms all its steps
at once and is done when all are.

A step has *started* once it fired; it has *ended* once the behaviour it started has
completed (`Behavior.ended`) and its group, if any, has ended (every step of it). A
behaviour replaced on its channel before it completes, or one without a natural end
(`idm`, `keep_gap`, `walk` without a distance or duration), never ends. Named steps record these states for
`started(...)`/`ended(...)`.
"""

from __future__ import annotations

from collections.abc import Callable

from addt_dsl.runtime.bound import BoundClause, BoundGroup, BoundStep

TIME_EPS_S = 1e-9

# holds(condition) -> bool on the current state; start(clause, time_s) starts a behaviour
# and returns it; ended(behavior, time_s) -> whether that behaviour has completed.
Holds = Callable[[object], bool]
Start = Callable[[BoundClause, float], object]
Ended = Callable[[object, float], bool]


class StepState:
    def __init__(self, step: BoundStep):
        self.clause = step.clause
        self.at_s = step.at_s
        self.after_s = step.after_s
        self.condition = step.condition
        self.hold_s = step.hold_s
        self.held_since: float | None = None  # first instant of the condition's current run
        self.edge = step.edge
        self.delay_s = step.delay_s
        self.last: bool | None = None  # the condition at its previous evaluation (edges)
        self.counted_at: float | None = None  # when the condition (its edge) counted (delay)
        self.repeats_left = step.repeat - 1  # firings after the first (`repeat N`)
        self.group = GroupState(step.group) if step.group is not None else None
        self.armed_at: float | None = None
        self.fired = False
        self.started = False  # it has fired at least once (stays so through `repeat`'s standby)
        self.label = step.label
        self.behavior = None  # the behaviour this step started
        self.ended = False

    def update_end(self, time_s: float, ended: Ended) -> bool:
        """Whether the step has ended (latched: once ended, it stays ended)."""
        if self.ended or not self.fired:
            return self.ended
        own = self.behavior is None or ended(self.behavior, time_s)
        group = self.group is None or self.group.update_end(time_s, ended)
        # `repeat N`: ended once its last firing's behaviour has (an OpenSCENARIO event is
        # complete when it has run maximumExecutionCount times).
        self.ended = own and group and self.repeats_left <= 0
        return self.ended

    def named(self):
        """This step and the steps under it that have a name."""
        if self.label is not None:
            yield self
        if self.group is not None:
            for s in self.group.steps:
                yield from s.named()

    @property
    def done(self) -> bool:
        return self.fired and self.repeats_left <= 0 and (self.group is None or self.group.done)

    def arm(self, time_s: float) -> None:
        if self.armed_at is None:
            self.armed_at = time_s

    def needs_state(self) -> bool:
        """Whether advancing now may evaluate a condition (so the caller builds a snapshot)."""
        if self.armed_at is None or self.done:
            return False
        if not self.fired or self.repeats_left > 0:
            return self.condition is not None
        return self.group is not None and self.group.needs_state()

    def rearm(self, time_s: float, ended: Ended | None) -> None:
        """`repeat N`: once its behaviour has ended, the step waits for its condition again
        (the edge's last value carries over, as an OpenSCENARIO event back in standby)."""
        if self.armed_at is not None and self.fired and self.repeats_left > 0 and ended is not None \
                and self.group is None and (self.behavior is None or ended(self.behavior, time_s)):
            self.repeats_left -= 1
            self.fired, self.counted_at, self.behavior = False, None, None
            if self.edge is None:  # (with an edge, the held level goes on: only its next edge counts)
                self.held_since = None

    def _waiting(self, time_s: float) -> bool:
        """Whether `after` or `at` still holds the step back at `time_s` (it is armed)."""
        return time_s + TIME_EPS_S < self.armed_at + self.after_s or \
            (self.at_s is not None and time_s + TIME_EPS_S < self.at_s)

    def asks(self, time_s: float):
        """The conditions `advance` at `time_s` will ask, as the step stands (one that its
        `advance` re-arms or arms first, it asks besides)."""
        if self.armed_at is None or self.done:
            return
        if not self.fired and self.condition is not None and self.counted_at is None and not self._waiting(time_s):
            yield self.condition
        if self.group is not None:
            yield from self.group.asks(time_s)

    def advance(self, time_s: float, holds: Holds, start: Start, ended: Ended | None = None) -> None:
        if self.armed_at is None:
            return
        self.rearm(time_s, ended)
        if self.done:
            return
        if not self.fired:
            if self._waiting(time_s):
                return
            if self.condition is not None and self.counted_at is None:
                value = holds(self.condition)
                # `when C for D`: the past-time `historically[0, D] C`, kept as the start of
                # C's current run of true samples rather than re-evaluating a window.
                if not value:
                    self.held_since = None
                elif self.held_since is None:
                    self.held_since = time_s
                value = value and time_s + TIME_EPS_S >= self.held_since + self.hold_s
                # An edge is an edge of the held condition (OpenSCENARIO's conditionEdge on a
                # condition with a duration): never at the first evaluation.
                last, self.last = self.last, value
                if self.edge is not None:
                    value = last is not None and value != last and (
                        self.edge == "changing" or value == (self.edge == "rising"))
                if not value:
                    return
                self.counted_at = time_s
            if self.counted_at is not None and time_s + TIME_EPS_S < self.counted_at + self.delay_s:
                return
            self.fired = self.started = True
            if self.clause is not None:
                self.behavior = start(self.clause, time_s)
            if self.group is not None:
                self.group.arm(time_s)
        if self.group is not None:
            self.group.advance(time_s, holds, start, ended)


class GroupState:
    def __init__(self, group: BoundGroup):
        self.mode = group.mode
        self.steps = [StepState(s) for s in group.steps]
        self.current = 0  # sequence: the step armed last

    @property
    def done(self) -> bool:
        return all(s.done for s in self.steps)

    def arm(self, time_s: float) -> None:
        if self.mode == "parallel":
            for s in self.steps:
                s.arm(time_s)
        elif self.steps:
            self.steps[0].arm(time_s)

    def needs_state(self) -> bool:
        return any(s.needs_state() for s in self.steps)

    def asks(self, time_s: float):
        for s in self.steps:
            yield from s.asks(time_s)

    def update_end(self, time_s: float, ended: Ended) -> bool:
        return all([s.update_end(time_s, ended) for s in self.steps])  # every step updated

    def advance(self, time_s: float, holds: Holds, start: Start, ended: Ended | None = None) -> None:
        if self.mode == "parallel":
            for s in self.steps:
                s.advance(time_s, holds, start, ended)
            return
        # A sequence may complete several zero-delay steps within one physics step.
        while self.current < len(self.steps):
            step = self.steps[self.current]
            step.advance(time_s, holds, start, ended)
            if not step.done or self.current + 1 == len(self.steps):
                return
            self.current += 1
            self.steps[self.current].arm(time_s)


class Script:
    """The top-level steps of one agent, all armed at time 0."""

    def __init__(self, steps: tuple[BoundStep, ...]):
        self.steps = [StepState(t) for t in steps]
        for s in self.steps:
            s.arm(0.0)
        self.named = [n for s in self.steps for n in s.named()]

    @property
    def done(self) -> bool:
        return all(s.done for s in self.steps)

    def needs_state(self) -> bool:
        return any(s.needs_state() for s in self.steps)

    def asks(self, time_s: float):
        """The conditions `advance` at `time_s` will ask, as the steps stand (`StepState.asks`)."""
        for s in self.steps:
            yield from s.asks(time_s)

    def advance(self, time_s: float, holds: Holds, start: Start, ended: Ended | None = None) -> None:
        # Every repeating step whose behaviour ended by now is back in standby before any step
        # fires (esmini ends an event in the step its action completes): a step firing first
        # must not replace that behaviour and so keep the other from ever re-arming.
        for s in self.steps:
            s.rearm(time_s, ended)
        for s in self.steps:
            s.advance(time_s, holds, start, ended)
