"""The fault base class, the schedule that applies faults, and bit-level helpers.

A fault kind's spec (`addt_dsl/specs/faults.py`) declares its settings (`ParamSpec`s) and
which targets it accepts (`valid_targets`, checked by the compiler); its implementation here
subclasses the spec and overrides the hooks it needs:

- `before_capture(sensor, t)`  the loop, before a sensor captures (extrinsics);
- `on_frame(frame, t)`         the loop, after capture: drop, delay, skew, corrupt data;
- `on_value(site, value, t)`   the stack, for every value through a scalar fault site;
- `on_state(site, state, t)`   the stack, when a node reads its stored state (a state site);
- `extra_latency(node, t, base)` the stack, when a node publishes;
- `bind(binding)`              once the stack exists: stack sites, tensor sites, clock, timers;
- `opened()`                   a window opened by a condition (`when C for W`) has its times now;
- `close()`                    at the end of the run: undo persistent side effects.

A fault whose window a condition opens (`opens`: a step's start) is closed (`start` is
infinite) until the schedule's `open_windows` sees the start fire, on the state recorded
at that sample; its window then counts from there and a `fault_window` event records it.
Its random draws do not depend on when that is: the same stream, drawn in the same order.

Every injection is recorded as a trace event `fault` with the same fields for every
kind: `index`, `kind`, `target`, `location` (where: sensor, site, node, tensor element)
and `value` (what was injected), plus kind-specific details. A kind that injects at the
rate of its site (`random_value`: every control tick) records a *series* instead: one
event per location whose `times`, `value` and `before` are parallel lists, one entry per
injection (`Trace.fault_injections()` expands both forms into one row per injection).
"""

from __future__ import annotations

import heapq
import math
import struct
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from addt_dsl.registry import FAULTS
from addt_dsl.runtime.bound import bind_step
from addt_dsl.runtime.script import StepState
from addt_dsl.specs import faults as S

# Bit ranges [lo, hi) of the IEEE-754 fields, by storage width in bits.
IEEE_FIELDS: dict[int, dict[str, tuple[int, int]]] = {
    64: {"sign": (63, 64), "exponent": (52, 63), "mantissa": (0, 52), "any": (0, 64)},
    32: {"sign": (31, 32), "exponent": (23, 31), "mantissa": (0, 23), "any": (0, 32)},
    16: {"sign": (15, 16), "exponent": (10, 15), "mantissa": (0, 10), "any": (0, 16)},
}
# bfloat16 shares float32's exponent width: 8 exponent bits, 7 mantissa bits.
IEEE_FIELDS_BF16 = {"sign": (15, 16), "exponent": (7, 15), "mantissa": (0, 7), "any": (0, 16)}
BIT_FIELDS_F64 = IEEE_FIELDS[64]
FIELD_NAMES = S.FIELD_NAMES


def flip_float64_bit(value: float, bit: int) -> float:
    """`value` with bit `bit` (0 = least significant mantissa bit, 63 = sign) inverted."""
    (bits,) = struct.unpack("<Q", struct.pack("<d", value))
    (out,) = struct.unpack("<d", struct.pack("<Q", bits ^ (1 << bit)))
    return out


def flip_int64_bit(value: int, bit: int) -> int:
    """`value` stored as a two's-complement int64 with bit `bit` (63 = sign) inverted."""
    out = (int(value) & 0xFFFF_FFFF_FFFF_FFFF) ^ (1 << bit)
    return out - (1 << 64) if out >= 1 << 63 else out


def flip_stored_bit(value: float | int, bit: int) -> float | int:
    """A stored state element with bit `bit` inverted: integers (lane ids, stages) as int64,
    everything else as float64."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        return flip_int64_bit(value, bit)
    return flip_float64_bit(float(value), bit)


_PLAIN = (float, int, str, bool, type(None))


def plain(value):
    """A value as plain Python data, so trace events hash and serialise the same everywhere."""
    if type(value) in _PLAIN:  # the common case, checked first: this runs per injection
        return value
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


@dataclass
class Binding:
    """What a fault may know about the running stack once it exists.

    `nodes` maps node name → scalar site names; `tensor_sites` maps a tensor site name
    (`perception.backbone_0`) → the torch module that owns it (empty without a learned
    model); `clock()` is the current simulated time [s]; `at(time_s, callback)` calls
    `callback()` at the start of the first step at or after `time_s` (the schedule's
    timers: tensor faults attach their hooks only then). Without a loop to drive timers
    (a bare `Binding`), `at` calls back at once.
    """

    nodes: Mapping[str, Iterable[str]] = field(default_factory=dict)
    tensor_sites: Mapping[str, object] = field(default_factory=dict)
    clock: Callable[[], float] = lambda: 0.0
    at: Callable[[float, Callable[[], None]], None] = lambda time_s, callback: callback()

    def sites(self) -> set[str]:
        return {s for sites in self.nodes.values() for s in sites}


class FaultKind(S.FaultSpec):
    def __init__(self, fault, step_s: float, duration_s: float, record):
        self.fault = fault
        self.settings = {p.name: fault.settings.get(p.name, p.default) for p in self.params}
        self.step_s = step_s
        self.instant = fault.end_s is not None and fault.end_s == fault.start_s
        if getattr(fault, "opens", None) is None:
            self._window_from(0.0)
        else:  # closed until its start fires (`open`)
            self.start = self.end = math.inf
        # Each fault draws from its own generator: adding or removing another fault never
        # changes when or how this one fires.
        self.rng = np.random.default_rng(fault.seed)
        self._record = record  # callable(time_s, detail dict)
        self.duration_s = duration_s
        self._series: dict[str, tuple[list, list, list]] = {}  # location -> (times, value, before)

    def _window_from(self, origin_s: float) -> None:
        """The window [start, end] [s] of times counted from `origin_s` (0, or where it opened)."""
        f = self.fault
        self.start = origin_s + f.start_s
        self.end = origin_s + f.end_s if f.end_s is not None else math.inf
        if self.instant:
            self.end = self.start + self.step_s * 0.999

    def open(self, time_s: float) -> None:
        """The condition that opens the window fired at `time_s` [s]."""
        self._window_from(time_s)
        self.opened()

    def active(self, time_s: float) -> bool:
        return self.start <= time_s <= self.end

    def record(self, time_s: float, location, value, **detail) -> None:
        """Record one injection: where (`location`) and what (`value`), plus details."""
        detail["location"], detail["value"] = location, value
        self._record(time_s, {k: plain(v) for k, v in detail.items()})

    def record_series(self, time_s: float, location: str, value: float, before: float) -> None:
        """Record one injection of a high-rate fault in its location's series event.

        The event is appended at the location's first injection (so events stay in time
        order) and its columns grow in place: three list appends per injection instead
        of an event each, which at 100 Hz cost more than the fault itself.
        """
        series = self._series.get(location)
        if series is None:
            series = self._series[location] = ([], [], [])
            self._record(time_s, {"location": location, "times": series[0], "value": series[1],
                                  "before": series[2]})
        series[0].append(time_s)
        series[1].append(value)
        series[2].append(float(before))

    # ---- hooks; a kind overrides the ones it needs
    def bind(self, binding: Binding) -> None:
        pass

    def opened(self) -> None:
        pass

    def close(self) -> None:
        pass

    def before_capture(self, sensor, time_s: float) -> None:
        pass

    def on_frame(self, frame, time_s: float):
        """Return (frame or None if dropped, extra delivery delay [s])."""
        return frame, 0.0

    def on_value(self, site: str, value: float, time_s: float) -> float:
        return value

    def on_state(self, site: str, state: list, time_s: float) -> bool:
        """A node is about to read its stored state `site`: `state` is its (name, value)
        pairs in memory order; edit the values in place. True when something changed."""
        return False

    def extra_latency(self, node: str, time_s: float, base_s: float) -> float:
        return 0.0


class FaultSchedule:
    """The concrete faults of one run, indexed by target for the loop's and stack's hooks.

    A fault on a node name (`bitflip control count 3`) also applies to the node's scalar
    sites once the schedule is bound to the stack (`bind`).
    """

    def __init__(self, faults, step_s: float, duration_s: float, events: list):
        from addt_dsl.runtime.trace import Event

        self.by_target: dict[str, list[FaultKind]] = {}
        self.events = events
        self.kinds: list[FaultKind] = []
        # Timers (`Binding.at`): (time [s], order of arming, callback), a heap. The loop
        # compares one float per step (`next_wake_s`, inf without timers) and calls `wake`.
        self._timers: list[tuple[float, int, Callable[[], None]]] = []
        self._timer_seq = 0
        self.next_wake_s = math.inf
        # Windows a condition opens (`when C for W`): (its start, armed at 0 s; the fault), in
        # schedule order; each leaves the list once it fired.
        self.openers: list[tuple[StepState, FaultKind]] = []
        for f in faults:
            cls = FAULTS.implementation(f.kind)

            def record(time_s, detail, _f=f):
                events.append(Event(time_s, "fault", {"index": _f.index, "kind": _f.kind,
                                                      "target": _f.target, **detail}))

            kind = cls(f, step_s, duration_s, record)
            self.kinds.append(kind)
            self.by_target.setdefault(f.target, []).append(kind)
            if getattr(f, "opens", None) is not None:
                self.openers.append((StepState(bind_step(f.opens, {})), kind))
        for opener, _ in self.openers:
            opener.arm(0.0)

    def bind(self, stack, clock: Callable[[], float]) -> None:
        """Tell every fault about the stack: its nodes and sites, its tensor sites, the clock.

        Scalar-site faults on a node are added to each of the node's sites, its state sites
        (`stack.state_nodes`: node → stored-state sites) included. A site fault
        whose target the stack does not have is an error (the compiler checks targets
        against the stack class; this catches a plan run against a different stack). A stack
        with `take_internal_faults(faults)` is handed every fault that is not a sensor's
        (the bridge's client: the remote stack applies them) and they leave this schedule.
        """
        hand_over = getattr(stack, "take_internal_faults", None)
        if hand_over is not None:
            # A stack that applies its internal faults itself (the bridge sends them to the
            # remote stack, which runs this same machinery): only sensor faults stay here.
            # It has no scenario state to open a window on (the compiler refuses it, E0204).
            waiting = [k.fault for _, k in self.openers if k.target_kind != "sensor"]
            if waiting:
                raise ValueError(f"fault '{waiting[0].kind}' on '{waiting[0].target}' waits for a condition, "
                                 "which a remote stack cannot evaluate")
            hand_over([k.fault for k in self.kinds if k.target_kind != "sensor"])
            self.kinds = [k for k in self.kinds if k.target_kind == "sensor"]
            kept = {t: [k for k in ks if k.target_kind == "sensor"] for t, ks in self.by_target.items()}
            self.by_target = {t: ks for t, ks in kept.items() if ks}
        state = getattr(stack, "state_nodes", {})
        nodes = {n: (*s, *state.get(n, ())) for n, s in getattr(stack, "nodes", {}).items()}
        tensor_sites = stack.tensor_sites() if hasattr(stack, "tensor_sites") else {}
        binding = Binding(nodes, tensor_sites, clock, self.at)
        known = binding.sites() | set(nodes) | set(tensor_sites)
        for kind in self.kinds:
            if kind.target_kind == "site" and kind.fault.target not in known:
                raise ValueError(f"fault '{kind.fault.kind}' targets '{kind.fault.target}', which the stack "
                                 f"does not have (sites: {', '.join(sorted(known))})")
            kind.bind(binding)
        for node, sites in nodes.items():
            node_faults = [k for k in self.by_target.get(node, []) if k.target_kind == "site"]
            for site in sites if node_faults else ():
                self.by_target.setdefault(site, []).extend(node_faults)

    def at(self, time_s: float, callback: Callable[[], None]) -> None:
        """Call `callback()` from `wake` at the first step at or after `time_s` [s]."""
        heapq.heappush(self._timers, (float(time_s), self._timer_seq, callback))
        self._timer_seq += 1
        self.next_wake_s = self._timers[0][0]

    def wake(self, time_s: float) -> None:
        """Run the timers due at `time_s` (the loop calls this when `time_s >= next_wake_s`),
        in time order, then in the order they were set; a callback may set new timers."""
        timers = self._timers
        while timers and timers[0][0] <= time_s + 1e-12:
            heapq.heappop(timers)[2]()
        self.next_wake_s = timers[0][0] if timers else math.inf

    def open_windows(self, time_s: float, holds: Callable[[object], bool]) -> None:
        """Open the windows whose start fires now (`holds(condition)` on the state recorded at
        `time_s`, the steps that fired at this sample included); one-shot, as a step without
        `repeat`. Due timers (a tensor flip at the opening instant) wake at once."""
        from addt_dsl.runtime.trace import Event

        waiting = []
        for opener, kind in self.openers:
            opener.advance(time_s, holds, lambda clause, t: None)
            if not opener.fired:
                waiting.append((opener, kind))
                continue
            kind.open(time_s)
            f = kind.fault
            self.events.append(Event(time_s, "fault_window", {
                "index": f.index, "kind": f.kind, "target": f.target, "start_s": kind.start,
                "end_s": None if math.isinf(kind.end) else (kind.start if kind.instant else kind.end)}))
        self.openers = waiting
        if time_s + 1e-12 >= self.next_wake_s:
            self.wake(time_s)

    def upset(self, node, time_s: float) -> None:
        """Memory faults in a node's stored state, applied when the node is about to read it.

        `node` declares `state_sites` and offers `read_state(site)` ((name, value) pairs in
        memory order) and `write_state(site, values)`. A flip changes the stored value in
        place: it stays until the node's own logic overwrites it.
        """
        for site in node.state_sites:
            kinds = self.by_target.get(site)
            if kinds:
                state = node.read_state(site)
                if any([f.on_state(site, state, time_s) for f in kinds]):  # a list: every fault sees it
                    node.write_state(site, [v for _, v in state])

    def close(self) -> None:
        """Undo persistent side effects (e.g. flipped weights of a model cached across runs)."""
        for kind in reversed(self.kinds):
            kind.close()

    def for_target(self, target: str) -> list[FaultKind]:
        return self.by_target.get(target, [])

    def targets(self) -> set[str]:
        return set(self.by_target)
