"""Triggers: conditions on the state just recorded (`when ...` of scripted steps, light
changes, environment changes, `end when ...`), read from a one-sample trace snapshot."""

from __future__ import annotations

import numpy as np

from addt_dsl.expr import Temporal, Until, walk
from addt_dsl.registry import ENVIRONMENTS, SIGNALS
from addt_dsl.runtime import oracles
from addt_dsl.runtime.signals import compute_signals
from addt_dsl.runtime.trace import ActorTrack, Event, Trace


def condition_checker(run, rec, k: int):
    """`holds(condition)` on the state recorded at sample k (`rec`: the run's
    `phases.Record`); the snapshot is taken at the first condition asked for."""
    snapshot = None

    def holds(condition) -> bool:
        nonlocal snapshot
        conditions = run.conditions
        answer = conditions.answered(condition, k)
        if answer is not None:
            return answer
        if snapshot is None:
            snapshot = conditions.snapshot(rec, k)
        formula = conditions.formula(condition)
        return bool(oracles.satisfied(formula, compute_signals(snapshot, formula.signals), run.dt))

    return holds


class Conditions:
    """What a run's trigger conditions and live settings read, kept over the run: each
    formula checked once (`oracles.prepare`: its sort and signals), and two one-sample
    `Trace` snapshots of the recorded state (with the named steps' states, for conditions;
    without, for live settings: whether a step ended can itself ask a live setting).

    A snapshot is one `Trace` whose actors' series are views of a buffer: taking it at a
    sample copies that sample's row of the record into the buffer (building the tracks
    anew cost ~11 us a condition, asked at every sample until it fires). A snapshot taken
    again replaces the last one's values: a condition checker takes it at its first
    condition and reads it for the rest of its phase."""

    def __init__(self, run):
        self.run = run
        # id -> (expr kept alive, its formula, `shared_key`)
        self._formulas: dict[int, tuple[object, oracles.Formula, str | None]] = {}
        self._snapshots: dict[bool, _Snapshot] = {}
        self._answers: dict[int, tuple[object, int, bool]] = {}  # id -> (condition, sample, verdict): `prefetch`

    def _prepared(self, expr) -> tuple[object, oracles.Formula, str | None]:
        got = self._formulas.get(id(expr))
        if got is None or got[0] is not expr:
            formula = oracles.prepare(expr)
            got = self._formulas[id(expr)] = (expr, formula, repr(formula.expr) if _alike(formula) else None)
        return got

    def formula(self, expr) -> oracles.Formula:
        return self._prepared(expr)[1]

    def shared_key(self, condition) -> str | None:
        """What runs asking `condition` alike share (its formula's text), or None where it
        cannot be answered with others' (`_alike`)."""
        return self._prepared(condition)[2]

    def answer(self, condition, k: int, verdict: bool) -> None:
        """`condition`'s verdict on the state recorded at sample k, found beforehand (`prefetch`)."""
        self._answers[id(condition)] = (condition, k, verdict)

    def answered(self, condition, k: int) -> bool | None:
        """The verdict `answer` gave `condition` at sample k, or None."""
        got = self._answers.get(id(condition))
        return got[2] if got is not None and got[0] is condition and got[1] == k else None

    def snapshot(self, rec, k: int, with_steps: bool = True) -> Trace:
        snap = self._snapshots.get(with_steps)
        if snap is None or snap.rec is not rec:
            snap = self._snapshots[with_steps] = _Snapshot(self.run, rec, with_steps)
        return snap.take(k)

    def live_value(self, expr, rec, k: int) -> float:
        """A live setting's value on the state recorded at sample k (no step states)."""
        formula = self.formula(expr)
        snap = self._snapshots.get(False)
        if snap is None or snap.rec is not rec or snap.k != k:
            self.snapshot(rec, k, with_steps=False)
            snap = self._snapshots[False]
        return float(oracles.evaluate(formula, compute_signals(snap.trace, formula.signals), self.run.dt)[0])


class _Snapshot:
    """One reused one-sample `Trace` of a run's record (`Conditions`)."""

    def __init__(self, run, rec, with_steps: bool):
        self.run, self.rec, self.with_steps = run, rec, with_steps
        self.k = -1
        sizes = {"ego": (run.ego_plan.length_m, run.ego_plan.width_m)}
        sizes.update({a.name: (a.length_m, a.width_m) for a in run.agents})
        frames = {"ego": run.ego_road.road_id}
        frames.update({a.name: run.agent_roads[a.name].road_id for a in run.agents})
        fields = tuple(rec.rec[rec.names[0]])
        # [actor, field, 1]: each series a one-sample view; a row of the record's block goes in at once.
        self._rows = np.zeros((len(rec.names), len(fields), 1))
        actors = {name: ActorTrack(name, *sizes[name], **dict(zip(fields, self._rows[i])), frame=frames[name])
                  for i, name in enumerate(rec.names)}
        self._latency = {n: np.zeros(1) for n in run.stack.latency}
        self._lights = {n: np.zeros(1) for n in run.lights.programs} if run.lights else {}
        self.trace = Trace(run.dt, np.zeros(1), actors, self._latency, lights=self._lights,
                           object_count=np.zeros(1))

    def take(self, k: int) -> Trace:
        run, rec, trace = self.run, self.rec, self.trace
        self.k = k
        self._rows[:, :, 0] = rec.block[k]
        t = k * run.dt
        trace.time[0] = t
        for n, v in run.stack.latency.items():
            series = self._latency.get(n)
            if series is None:
                series = self._latency[n] = np.zeros(1)
            series[0] = v
        for n, v in self._lights.items():
            v[0] = run.lights.state(n, t)
        trace.object_count[0] = float(run.stack.objects_seen)  # (as `outputs` records it at k)
        trace.red_margin = {n: v[k:k + 1] for n, v in run.red_margins.items()}
        trace.stop_margin = {n: v[k:k + 1] for n, v in run.sign_margins.items()}
        trace.road_edge = {n: v[k:k + 1] for n, v in run.edges.items()}
        trace.road_end = {n: v[k:k + 1] for n, v in run.ends.items()}
        trace.variables = {n: v[k:k + 1] for n, v in run.variable_records.items()}
        trace.wrong_way = {n: v[k:k + 1] for n, v in run.wrong_ways.items()}
        trace.off_lanes = {n: v[k:k + 1] for n, v in run.offs.items()}
        if run.lane_ids:  # `lane_id(A)` reads the lanes now
            trace.lanes = {name: np.array([run.lane_number(name)]) for name in rec.names}
        if run.named_steps and self.with_steps:  # `when ended(lead.brake_hard)` reads the states now
            trace.steps = {name: np.array([code], dtype=np.int8) for name, code in run.step_states(t).items()}
        return trace


def _alike(formula: oracles.Formula) -> bool:
    """Whether runs asking `formula` can be answered in one evaluation, a sample per run: no
    temporal operator (a sample's verdict is its own) and signals of the recorded state only
    (not the named steps' states, which steps firing earlier in the phase change)."""
    if not formula.signals or any(isinstance(n, (Temporal, Until)) for n in walk(formula.expr)):
        return False
    specs = [SIGNALS.get(name.partition("(")[0]) for name in formula.signals]
    return all(spec is not None and "step" not in spec.args for spec in specs)


def prefetch(runs: list, recs: list, k: int) -> None:
    """Over the batch: the `when` conditions the runs' scripts will ask at sample k
    (`Script.asks`) that several runs ask alike (equal formulas, `_alike`) are evaluated
    together: each run's signals from its own snapshot, stacked a sample per run, one
    evaluation (the evaluator works sample by sample: each run's verdict is the one it gets
    alone); `condition_checker` takes the runs' verdicts from there. A group whose signals
    raise is left to the runs, which raise alone."""
    if len(runs) < 2:
        return
    groups: dict[str, tuple[oracles.Formula, list]] = {}  # (in the order first asked)
    for run, rec in zip(runs, recs):
        if not run.scripts:
            continue
        t = k * run.dt
        for script in run.scripts.values():
            for condition in script.asks(t):
                key = run.conditions.shared_key(condition)
                if key is not None:
                    group = groups.get(key)
                    if group is None:
                        group = groups[key] = (run.conditions.formula(condition), [])
                    group[1].append((run, rec, condition))
    for formula, members in groups.values():
        if len(members) < 2:
            continue
        try:
            rows = getattr(members[0][1], "batch_rows", None)  # (a batch's records: field signals from its block)
            recs = [rec for _, rec, _ in members]
            stacked = rows.field_values(k, recs, formula.signals) if rows is not None else None
            if stacked is None:
                signals = [compute_signals(run.conditions.snapshot(rec, k), formula.signals)
                           for run, rec, _ in members]
                stacked = {name: np.concatenate([s[name] for s in signals]) for name in formula.signals}
            verdicts = oracles.verdicts(formula, stacked, members[0][0].dt).tolist()
        except Exception:  # noqa: BLE001 - each run asks again alone and raises there
            continue
        for (run, _, condition), verdict in zip(members, verdicts):
            run.conditions.answer(condition, k, verdict)


def advance_scripts(run, rec, k: int, t_now: float) -> None:
    holds = condition_checker(run, rec, k)

    for name, script in list(run.scripts.items()):
        agent = run.ego_agent if name == "ego" else run.agent_by_name[name]

        def start(clause, time_s, _agent=agent, _name=name) -> None:
            run.events.append(Event(time_s, "trigger", {"actor": _name, "behavior": clause.name}))
            return run._start_behavior(_agent, clause, time_s)

        script.advance(t_now, holds, start, lambda beh, time_s, _agent=agent: run.behavior_ended(_agent, beh, time_s))
        if script.done:
            del run.scripts[name]


def advance_light_script(run, rec, k: int, t_now: float) -> None:
    holds = condition_checker(run, rec, k)

    def start(clause, time_s) -> None:
        run.events.append(Event(time_s, "trigger", {"light": clause.name, "state": clause.settings["state"]}))
        run.lights.change(clause.name, time_s, clause.settings["state"])

    run.light_script.advance(t_now, holds, start)
    if run.light_script.done:
        run.light_script = None


def advance_variable_script(run, rec, k: int, t_now: float) -> None:
    def start(clause, time_s) -> None:
        run.events.append(Event(time_s, "variable", {"variable": clause.name, "value": clause.settings["value"]}))
        run.variables[clause.name] = float(clause.settings["value"])

    run.variable_script.advance(t_now, condition_checker(run, rec, k), start)
    if run.variable_script.done:
        run.variable_script = None


def advance_environment_script(run, rec, k: int, t_now: float) -> None:
    def start(clause, time_s) -> None:
        run.events.append(Event(time_s, "environment", {"model": clause.name, **clause.settings}))
        model = ENVIRONMENTS.implementation(clause.name)(clause.settings)
        at = next((i for i, m in enumerate(run.environment) if m.keyword == clause.name), None)
        if at is None:  # a model not declared before acts from now on, after the others
            run.environment.append(model)
        else:
            run.environment[at] = model
        run.apply_friction()

    run.environment_script.advance(t_now, condition_checker(run, rec, k), start)
    if run.environment_script.done:
        run.environment_script = None
