"""Shrinking a failing run to a minimal counterexample that fails the same way.

A hand-written pass engine in the style of Hypothesis's conjecture shrinker: explicit
passes, each proposing simpler candidates of the current best; a candidate is accepted
when it still shows the target failure (same oracle, same mode, see `outcome`) and its
`sort_key` is strictly smaller; the passes repeat until a whole round changes nothing
(a fixed point) or the simulation budget is spent. Every run goes through a `RunCache`
keyed by `RunSpec.key()`, so no candidate is simulated twice.

Why not Hypothesis's own engine (`find`): it shrinks a byte stream of choices, which
would hide the structure that makes these passes cheap (delete a fault, cut a window at
the violation time, fix the bit that was actually flipped), it gives no control over
the number of simulations (each costs 0.1-1 s, Hypothesis budgets in thousands of
calls), and its notion of "the same failure" is an exception's type and location. The
passes below are explicit, with per-pass statistics.

A candidate must also compile as the `.addt` file it will be written as (`printer.check_spec`):
a shorter run can end before a `reach goal within T`, a window, a fault time or a step
tied to it, and such a candidate is refused as a step (counted in `rejected`), never
written. The check costs milliseconds next to a simulation, and is done once per candidate.

Batches (`batch` > 1): where a candidate must be simulated, the shrink runs it together
with the candidates the pass would propose next were each of them rejected (a look-ahead:
the pass replayed from its start with its answers so far, unknown candidates assumed not to
fail), up to `batch` runs stepped together (`RunCache.get_many`: the batch engine, on
`jobs` workers). The pass then goes on as at batch 1 and takes the first failing candidate
in its own order, never by finish order; the runs after it were run ahead for nothing.
So the kept candidates, the result, its per-pass stats, `simulations` and `cache_hits` are
those of batch 1. The budget counts every run: `simulations` (candidates judged) plus
`ran_ahead` (run ahead, never judged) stays within `max_simulations`; a batch is cut to the
budget left. What is true (tests/unit/search/test_shrink_batches.py):
  - a shrink at batch N that does not spend its budget ends exactly as at batch 1;
  - one that spends it ends exactly as the batch-1 shrink given a budget of its
    `simulations` (it stops at the same candidate, having kept the same ones before).

Passes, in order (cheap large steps first, like conjecture):
  cut_after_violation  faults and the run end where the failure is decided (the first
                       violation plus the formula's look-ahead; nothing later matters)
  delete_faults        adaptive chunk deletion (halves, quarters, ..., single faults)
  delete_agents        same, for agents no kept oracle or trigger refers to
  shorten_windows      instantaneous, then bisect the end down and the start up
  reduce_settings      counts and magnitudes bisected toward neutral (0, 1, no slowdown);
                       bit flips: fix the bit that flipped, then bisect toward bit 0
  drop_settings        settings removed (back to their defaults)
  params_to_nominal    parameters to their nominal values, else bisected toward them
  simplify_numbers     numbers rounded toward the simple side (fewer digits)
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from addt_dsl import expr as E
from addt_dsl.plan import RunSpec, ScenarioPlan
from addt_dsl.printer import check_spec, semantic_key
from addt_dsl.registry import FAULTS
from addt_dsl.runtime.result import Failure, RunResult
from addt_dsl.search import candidates as C
from addt_dsl.search.cache import RunCache
from addt_dsl.sweep import violated_assumptions

BISECT_STEPS = 5


@dataclass
class PassStats:
    name: str
    candidates: int = 0  # proposed (cache hits included)
    simulations: int = 0
    accepted: int = 0
    rejected: int = 0  # candidates that do not compile as a scenario (not simulated)
    seconds: float = 0.0


@dataclass
class ShrinkResult:
    original: RunSpec  # pinned form of the input
    best: RunSpec
    outcome: RunResult
    target: Failure  # the failure as the best run shows it
    stats: list[PassStats]
    simulations: int
    cache_hits: int
    rounds: int
    budget_exhausted: bool
    seconds: float
    changes: list[str] = field(default_factory=list)  # what did not matter / was reduced
    scenario_key: str = ""  # `semantic_key` of the scenario shrunk from: ties a corpus entry to its content
    ran_ahead: int = 0  # runs a batch ran ahead that the shrink never judged (0 at batch 1)
    batch: int = 1


class NotFailing(ValueError):
    """The run to shrink does not fail (or not the requested oracle)."""


class _Ahead(Exception):
    """A look-ahead has its batch (or lost its way): stop replaying the pass."""


@dataclass
class _Replay:
    """A pass replayed for its look-ahead: the answers it had (`log`), then the candidates
    it would propose were each unknown one rejected (`collected`, at most `size`)."""

    log: list[tuple[str, bool, RunResult | None]]
    size: int
    pos: int = 0
    collected: list[RunSpec] = field(default_factory=list)
    keys: set[str] = field(default_factory=set)


class Shrinker:
    def __init__(self, spec: RunSpec, *, nominal_plan: ScenarioPlan | None = None, oracle: str | None = None,
                 cache: RunCache | None = None, max_simulations: int = 300,
                 log: Callable[[str], None] | None = None, batch: int = 1, jobs: int = 1):
        self.cache = cache or RunCache()
        self.max_simulations = max_simulations
        self.batch = max(1, batch)  # candidates run together where one must be simulated
        self.jobs = max(1, jobs)  # workers a batch runs on
        self.log = log or (lambda msg: None)
        self.repeats = 0  # candidates proposed again after this shrink judged them (`cache_hits`)
        # Distinct runs this shrink judged, cached or not: its budget and its `simulations`
        # count these, so a shrink ends the same whatever the cache held before (a killed
        # shrink run again resumes from its cache and ends with the same result).
        self.judged: set[str] = set()
        # Runs this shrink asked for, judged or run ahead (cached or not): the budget bounds these.
        self.seen: set[str] = set()
        # The pass running, the best run at its start and its answers so far (the look-ahead replays them).
        self._pass: Callable[[], None] | None = None
        self._pass_start: tuple[RunSpec, RunResult] | None = None
        self._answers: list[tuple[str, bool, RunResult | None]] = []
        self._replay: _Replay | None = None
        self.compiles_cache: dict[str, bool] = {}
        plan = nominal_plan or spec.plan
        self.nominal = plan.nominal_params()
        self.scales = {p.name: (p.high - p.low) if p.low is not None and p.high is not None and p.high > p.low
                       else max(1.0, abs(p.default)) for p in plan.params}
        self.assumptions_plan = plan
        self.scenario_key = semantic_key(plan)
        self.best = C.pinned(spec)
        self.original = self.best
        self.judged.add(self.best.key())
        self.seen.add(self.best.key())
        self.kept: list[str] = []  # keys of the candidates accepted, in order
        self.outcome = self.cache.get(self.best)
        failure = (self.outcome.primary() if oracle is None else
                   next((f for f in self.outcome.failures if f.oracle == oracle), None))
        if failure is None:
            what = "does not fail" if oracle is None else f"does not fail oracle '{oracle}'"
            raise NotFailing(f"the run {what}; nothing to shrink")
        self.target = failure.id
        self.stats: list[PassStats] = []
        self._current: PassStats | None = None
        self.exhausted = False

    # ---- the engine
    @property
    def simulations(self) -> int:
        return len(self.judged)

    def key(self, spec: RunSpec) -> tuple:
        return C.sort_key(spec, self.nominal, self.scales)

    def interesting(self, outcome: RunResult) -> bool:
        return outcome.failure(self.target) is not None

    @property
    def ran_ahead(self) -> int:
        return len(self.seen - self.judged)

    def consider(self, candidate: RunSpec, extra: Callable[[RunResult], bool] | None = None) -> bool:
        """Run `candidate` (cached); make it the best if it fails the same way and is simpler."""
        if self._replay is not None:
            return self._consider_ahead(candidate, extra)
        if self.exhausted:
            return False
        if not self.key(candidate) < self.key(self.best):
            return self._answer("", False)
        if violated_assumptions(self.assumptions_plan, {**self.nominal, **candidate.params}):
            return self._answer("", False)
        key = candidate.key()
        new = key not in self.judged
        if key not in self.seen and len(self.seen) >= self.max_simulations:
            self.exhausted = True
            return False
        if not self.compiles(candidate, key):
            if self._current is not None:
                self._current.rejected += 1
            return self._answer(key, False)
        if key not in self.seen:
            self._simulate(candidate, key)
        self.judged.add(key)
        self.repeats += not new
        outcome = self.cache.get(candidate)
        st = self._current
        if st is not None:
            st.candidates += 1
            st.simulations += new
        if not self.interesting(outcome) or (extra is not None and not extra(outcome)):
            return self._answer(key, False)
        self.best, self.outcome = candidate, outcome
        self.kept.append(key)
        if st is not None:
            st.accepted += 1
        return self._answer(key, True, outcome)

    def _answer(self, key: str, accepted: bool, outcome: RunResult | None = None) -> bool:
        self._answers.append((key, accepted, outcome))
        return accepted

    def _simulate(self, candidate: RunSpec, key: str) -> None:
        """Simulate `candidate`, with the candidates the pass would propose after it (`look_ahead`)."""
        room = self.max_simulations - len(self.seen)
        batch = [candidate]
        if self.batch > 1 and room > 1 and self._pass is not None:
            batch = self.look_ahead(candidate, key, min(self.batch, room))
        self.cache.get_many(batch, self.jobs)
        self.seen.update(s.key() for s in batch)

    def look_ahead(self, candidate: RunSpec, key: str, size: int) -> list[RunSpec]:
        """`candidate` and the next candidates to simulate were it and each of them rejected:
        the running pass replayed from its start with the answers it had (no stats, no runs),
        then every candidate not yet run taken as not failing, until `size` are found (or
        the pass ends). Candidates this shrink has results for are answered as they will be."""
        replay = _Replay(list(self._answers), size)
        saved = (self.best, self.outcome, self._current, self._answers)
        self.best, self.outcome = self._pass_start
        self._current, self._replay = None, replay
        try:
            self._pass()
        except _Ahead:
            pass
        finally:
            self.best, self.outcome, self._current, self._answers = saved
            self._replay = None
        if not replay.collected or replay.collected[0].key() != key:  # cannot happen: passes are deterministic
            return [candidate]
        return replay.collected

    def _consider_ahead(self, candidate: RunSpec, extra: Callable[[RunResult], bool] | None) -> bool:
        """`consider` while replaying a pass for its look-ahead."""
        r = self._replay
        if r.pos < len(r.log):  # answered before: the same answer
            key, accepted, outcome = r.log[r.pos]
            r.pos += 1
            if accepted:
                self.best, self.outcome = candidate, outcome
            return accepted
        r.pos += 1
        if not self.key(candidate) < self.key(self.best):
            return False
        if violated_assumptions(self.assumptions_plan, {**self.nominal, **candidate.params}):
            return False
        key = candidate.key()
        if key in self.seen:  # its result is known: the answer the pass will get
            if not self.compiles(candidate, key):
                return False
            outcome = self.cache.get(candidate)
            if not self.interesting(outcome) or (extra is not None and not extra(outcome)):
                return False
            self.best, self.outcome = candidate, outcome
            return True
        if key in r.keys or not self.compiles(candidate, key):
            return False
        r.collected.append(candidate)
        r.keys.add(key)
        if len(r.collected) >= r.size:
            raise _Ahead
        return False  # assumed: the look-ahead's candidates run as if each before failed to fail

    def run(self) -> ShrinkResult:
        try:
            return self._run()
        finally:
            self.cache.release_workers()  # the workers kept between batches

    def _run(self) -> ShrinkResult:
        t0 = time.perf_counter()
        passes = [self.cut_after_violation, self.delete_faults, self.delete_agents, self.shorten_windows,
                  self.reduce_settings, self.drop_settings, self.params_to_nominal, self.simplify_numbers]
        stats = {p.__name__: PassStats(p.__name__) for p in passes}
        self.stats = list(stats.values())
        rounds = 0
        while not self.exhausted:
            rounds += 1
            before = self.key(self.best)
            for p in passes:
                if self.exhausted:
                    break
                self._current = stats[p.__name__]
                self._pass, self._pass_start, self._answers = p, (self.best, self.outcome), []
                tp = time.perf_counter()
                p()
                self._current.seconds += time.perf_counter() - tp
                self._current, self._pass, self._pass_start, self._answers = None, None, None, []
            self.log(f"round {rounds}: {self.simulations} simulations, {len(self.best.faults)} fault(s)")
            if self.key(self.best) == before:
                break
        return ShrinkResult(self.original, self.best, self.outcome, self.outcome.failure(self.target), self.stats,
                            self.simulations, self.repeats, rounds, self.exhausted,
                            time.perf_counter() - t0, describe_changes(self.original, self.best, self.nominal),
                            self.scenario_key, self.ran_ahead, self.batch)

    def compiles(self, candidate: RunSpec, key: str | None = None) -> bool:
        """Whether `candidate` printed as a pinned `.addt` file compiles back (cached by key)."""
        key = key or candidate.key()
        ok = self.compiles_cache.get(key)
        if ok is None:
            try:
                check_spec(candidate)
                ok = True
            except ValueError:
                ok = False
            self.compiles_cache[key] = ok
        return ok

    # ---- helpers
    def violation_time(self) -> float | None:
        f = self.outcome.failure(self.target)
        return f.time_s if f else None

    def evidence_end(self) -> float | None:
        """Until when the trace decides the target failure: the first violation plus the
        look-ahead of the formula there (None: the whole run may matter)."""
        t_v = self.violation_time()
        if t_v is None:
            return None
        oracle = next((o for o in self.best.plan.oracles if o.name == self.target[0]), None)
        if oracle is None:  # stack_health: the run stopped at the error
            return t_v
        return evidence_end(E.substitute_params(oracle.formula, self.best.params), t_v)  # windows of this run

    def bisect(self, current: float, target: float, make: Callable[[float], RunSpec | None],
               integer: bool = False, steps: int = BISECT_STEPS) -> None:
        """Move a value from `current` toward `target`: try `target`, then bisect (the
        failing side moves toward the target)."""
        if current == target:
            return
        cand = make(target)
        if cand is not None and self.consider(cand):
            return
        lo, hi = target, current  # lo: not (known) failing, hi: failing
        for _ in range(steps):
            mid = (lo + hi) / 2
            if integer:
                mid = math.floor(mid) if hi > lo else math.ceil(mid)
                if mid in (lo, hi):
                    mid = hi - 1 if hi > lo else hi + 1
                    if mid == lo:
                        return
            cand = make(mid)
            if cand is not None and self.consider(cand):
                hi = mid
            else:
                lo = mid
            if self.exhausted or (not integer and abs(hi - lo) <= 1e-9 * max(1.0, abs(hi))):
                return

    # ---- passes
    def cut_after_violation(self) -> None:
        """Nothing after the first violation matters: drop faults that start after it,
        end the others there, and end the run shortly after (same failing oracles only)."""
        t_v = self.evidence_end()
        if t_v is None:
            return
        spec = self.best
        cut = []
        for e in C.entries(spec):
            f = e.fault
            if f.start_s >= t_v:
                continue
            # (A window a condition opens counts from there, at or after 0 s: a length of t_v
            # still covers all of it before the violation.)
            end = f.end_s if f.end_s is not None and f.end_s <= t_v else t_v
            cut.append(C.FaultEntry(f.model_copy(update={"end_s": end}), e.label))
        self.consider(C.rebuild(spec, faults=cut))
        for i, e in enumerate(C.entries(self.best)):  # one by one if the combined cut changed the failure
            f = e.fault
            if f.start_s >= t_v:
                self.consider(C.without_faults(self.best, [i]))
        plan = self.best.plan
        step = plan.step_s
        end = math.ceil((t_v + 0.5) / step - 1e-9) * step
        if end < plan.duration_s:
            failing = {f.oracle for f in self.outcome.failures}

            def shorter(d):
                return C.rebuild(self.best, plan_updates={"duration_s": round(d, 9)})

            cand = shorter(end)
            if not self.compiles(cand):
                if self._current is not None:
                    self._current.rejected += 1
                # Something is tied to the duration (`reach goal within 20 s`, a window, a
                # fault time): the shortest run that still compiles, found by compiling only.
                lo, hi = round(end / step), round(plan.duration_s / step)  # lo fails, hi compiles
                while hi - lo > 1:
                    mid = (lo + hi) // 2
                    lo, hi = (lo, mid) if self.compiles(shorter(mid * step)) else (mid, hi)
                cand = shorter(hi * step)
            self.consider(cand, extra=lambda o: {f.oracle for f in o.failures} <= failing)

    def delete_faults(self) -> None:
        self._adaptive_delete(lambda s: len(s.faults), lambda s, idx: C.without_faults(s, idx))

    def delete_agents(self) -> None:
        def count(s):
            return len(C.removable_agents(s, self.target[0]))

        def delete(s, idx):
            names = C.removable_agents(s, self.target[0])
            return C.without_agents(s, [names[i] for i in idx])

        self._adaptive_delete(count, delete)

    def _adaptive_delete(self, count: Callable[[RunSpec], int], delete: Callable[[RunSpec, list[int]], RunSpec]):
        """Delta debugging: delete chunks of size n, n/2, ..., 1; after a success retry
        the same position (the list shifted)."""
        k = count(self.best)
        while k >= 1 and not self.exhausted:
            i = 0
            while i < count(self.best) and not self.exhausted:
                idx = list(range(i, min(i + k, count(self.best))))
                if not self.consider(delete(self.best, idx)):
                    i += k
            k = k // 2 if k > 1 else 0

    def shorten_windows(self) -> None:
        for i in range(len(self.best.faults)):
            if i >= len(self.best.faults) or self.exhausted:
                break
            f = self.best.faults[i]
            duration = self.best.plan.duration_s
            end = duration if f.end_s is None else f.end_s
            if end <= f.start_s:
                continue
            if self.consider(C.with_fault(self.best, i, end_s=f.start_s)):
                continue
            start = f.start_s
            self.bisect(end, start, lambda e: C.with_fault(self.best, i, end_s=e) if e > start else None)
            end = self.best.faults[i].end_s
            end = duration if end is None else end
            if f.opens is not None:  # a window a condition opens starts where it fires: only its length shrinks
                continue
            self.bisect(start, end, lambda s: C.with_fault(self.best, i, start_s=s) if s < end else None)

    def reduce_settings(self) -> None:
        i = 0
        while i < len(self.best.faults) and not self.exhausted:
            f = self.best.faults[i]
            cls = FAULTS.get(f.kind)
            specs = {p.name: p for p in cls.params} if cls else {}
            drawn = C.drawn_setting(f.kind)
            if drawn is not None:
                self._fix_drawn(i, drawn)
            for name in sorted(self.best.faults[i].settings):
                value = self.best.faults[i].settings[name]
                spec = specs.get(name)
                if not isinstance(value, float) or spec is None or name == drawn:
                    continue
                integer = spec.kind == "int"
                self.bisect(value, C.neutral_value(f.kind, name),
                            lambda v, n=name: self._with_setting(i, n, float(v)), integer=integer)
            i += 1

    def _with_setting(self, i: int, name: str, value) -> RunSpec:
        f = self.best.faults[i]
        return C.with_fault(self.best, i, settings={**f.settings, name: value})

    def _fix_drawn(self, i: int, name: str) -> None:
        """Pin a drawn setting (a flipped bit) to the value the run drew, then lower it."""
        value = self.best.faults[i].settings.get(name, -1.0)
        if value < 0:
            drawn = self.outcome.drawn_values.get(i, ())
            if not drawn:
                return
            # Injection times are drawn before the values, so pinning the drawn value replays the run.
            if not self.consider(self._with_setting(i, name, float(max(drawn)))):
                return
            value = self.best.faults[i].settings[name]
        self.bisect(value, 0.0, lambda b: self._with_setting(i, name, float(b)), integer=True, steps=7)

    def drop_settings(self) -> None:
        for i in range(len(self.best.faults)):
            if i >= len(self.best.faults) or self.exhausted:
                break
            cls = FAULTS.get(self.best.faults[i].kind)
            required = {p.name for p in cls.params if p.required} if cls else set()
            for name in sorted(self.best.faults[i].settings):
                f = self.best.faults[i]
                if name in required or name not in f.settings:
                    continue
                self.consider(C.with_fault(self.best, i, settings={k: v for k, v in f.settings.items() if k != name}))

    def params_to_nominal(self) -> None:
        for name in sorted(self.best.params):
            if name not in self.nominal or self.exhausted:
                continue
            self.bisect(self.best.params[name], self.nominal[name],
                        lambda v, n=name: C.rebuild(self.best, params={**self.best.params, n: v}))

    def simplify_numbers(self) -> None:
        """Round each number toward its simple side: fewer digits, same or lower complexity."""
        for name in sorted(self.best.params):
            if name in self.nominal:
                self._round(self.best.params[name], self.nominal[name],
                            lambda v, n=name: C.rebuild(self.best, params={**self.best.params, n: v}))
        for i in range(len(self.best.faults)):
            if i >= len(self.best.faults):
                break
            f = self.best.faults[i]
            end = f.end_s
            self._round(f.start_s, end if end is not None else self.best.plan.duration_s,
                        lambda v: C.with_fault(self.best, i, start_s=v, end_s=v if end == f.start_s else end))
            f = self.best.faults[i]
            if f.end_s is not None and f.end_s != f.start_s:
                self._round(f.end_s, f.start_s, lambda v: C.with_fault(self.best, i, end_s=v))
            for name in sorted(self.best.faults[i].settings):
                v = self.best.faults[i].settings[name]
                if isinstance(v, float) and name != C.drawn_setting(f.kind):
                    self._round(v, C.neutral_value(f.kind, name), lambda x, n=name: self._with_setting(i, n, x))

    def _round(self, value: float, toward: float, make: Callable[[float], RunSpec]) -> None:
        for decimals in (0, 1, 2):
            scale = 10.0 ** decimals
            r = (math.ceil(value * scale) if toward > value else math.floor(value * scale)) / scale
            r = min(r, toward) if toward > value else max(r, toward)
            if r == value or self.exhausted:
                return
            if self.consider(make(r)):
                return


# ---------------------------------------------------------------- evidence

def horizon(e) -> float | None:
    """How far past a sample the formula looks (None: to the end of the trace)."""
    match e:
        case E.Temporal(hi_s=hi, arg=a):
            h = horizon(a)
            return None if hi is None or h is None else hi + h
        case E.Until(hi_s=hi, left=l, right=r):
            hs = [horizon(l), horizon(r)]
            return None if hi is None or None in hs else hi + max(hs)
    hs = [horizon(c) for c in E.children(e)]
    return None if None in hs else max(hs, default=0.0)


def evidence_end(formula, t_v: float) -> float | None:
    """`first_violation_time` is the failing sample of an `always` (or of a violated
    conjunct); anything else is judged at time 0 and may look as far as its horizon."""
    match formula:
        case E.Temporal(op="always", arg=a):
            h = horizon(a)
            return None if h is None else t_v + h
        case E.Binary(op="and", left=l, right=r):
            ends = [evidence_end(l, t_v), evidence_end(r, t_v)]
            return None if None in ends else max(ends)
    return horizon(formula)


# ---------------------------------------------------------------- report

def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def _window(f) -> str:
    if f.opens is not None:  # counted from where its condition fires
        return "when its condition holds" + (f", for {_fmt(f.end_s)} s" if f.end_s is not None else "")
    if f.end_s is None:
        return f"from {_fmt(f.start_s)} s"
    if f.end_s == f.start_s:
        return f"at {_fmt(f.start_s)} s"
    return f"during [{_fmt(f.start_s)} s, {_fmt(f.end_s)} s]"


def describe_changes(original: RunSpec, best: RunSpec, nominal: dict[str, float]) -> list[str]:
    """What did not matter (removed, reset) and what mattered only in part (reduced)."""
    out = []
    before = {e.label: e.fault for e in C.entries(original)}
    after = {e.label: e.fault for e in C.entries(best)}
    for label, f in before.items():
        if label not in after:
            out.append(f"did not matter: fault {f.kind} {f.target} {_window(f)} ({label})")
    for label, f in after.items():
        g = before.get(label)
        if g is None:
            continue
        if (g.start_s, g.end_s) != (f.start_s, f.end_s):
            out.append(f"reduced: fault {f.kind} {f.target} window {_window(g)} -> {_window(f)}")
        for k in sorted(set(g.settings) | set(f.settings)):
            if g.settings.get(k) != f.settings.get(k):
                out.append(f"reduced: fault {f.kind} {f.target} {k} {_fmt(g.settings.get(k, 'default'))} -> "
                           f"{_fmt(f.settings.get(k, 'default'))}")
    kept_agents = {a.name for a in best.plan.agents}
    for a in original.plan.agents:
        if a.name not in kept_agents:
            out.append(f"did not matter: agent {a.name}")
    kept_oracles = {o.name for o in best.plan.oracles}
    for o in original.plan.oracles:
        if o.name not in kept_oracles:
            out.append(f"dropped with its agent: oracle {o.name}")
    for k, v in original.params.items():
        if k in best.params and best.params[k] != v:
            what = "did not matter" if best.params[k] == nominal.get(k) else "reduced"
            out.append(f"{what}: parameter {k} {_fmt(v)} -> {_fmt(best.params[k])}"
                       + (" (nominal)" if best.params[k] == nominal.get(k) else ""))
    if original.plan.duration_s != best.plan.duration_s:
        out.append(f"reduced: duration {_fmt(original.plan.duration_s)} s -> {_fmt(best.plan.duration_s)} s")
    return out


def shrink(spec: RunSpec, **kwargs) -> ShrinkResult:
    return Shrinker(spec, **kwargs).run()
