"""Triggers: conditions on the state just recorded (`when ...` of scripted steps, light
changes, environment changes, `end when ...`), read from a one-sample trace snapshot."""

from __future__ import annotations

import numpy as np

from addt_dsl.registry import ENVIRONMENTS
from addt_dsl.runtime import oracles
from addt_dsl.runtime.signals import compute_signals
from addt_dsl.runtime.trace import ActorTrack, Event, Trace


def condition_checker(run, rec, k: int):
    """`holds(condition)` on the state recorded at sample k; the trace snapshot is built
    once, at the first condition asked for."""
    snapshot = None

    def holds(condition) -> bool:
        nonlocal snapshot
        if snapshot is None:
            snapshot = snapshot_trace(run, rec, k)
        sig = compute_signals(snapshot, oracles_signals(condition))
        return bool(oracles.satisfied(condition, sig, run.dt))

    return holds


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


def oracles_signals(expr) -> set[str]:
    from addt_dsl.expr import signals_used

    return signals_used(expr)


def snapshot_trace(run, rec, k: int, with_steps: bool = True) -> Trace:
    actors = {}
    sizes = {"ego": (run.ego_plan.length_m, run.ego_plan.width_m)}
    sizes.update({a.name: (a.length_m, a.width_m) for a in run.agents})
    frames = {"ego": run.ego_road.road_id}
    frames.update({a.name: run.agent_roads[a.name].road_id for a in run.agents})
    for name, r in rec.items():
        actors[name] = ActorTrack(name, *sizes[name], **{f: v[k:k + 1] for f, v in r.items()}, frame=frames[name])
    lat = {n: np.array([v]) for n, v in run.stack.latency.items()}
    t = k * run.dt
    lights = {n: np.array([run.lights.state(n, t)]) for n in run.lights.programs} if run.lights else {}
    trace = Trace(run.dt, np.array([t]), actors, lat, lights=lights,
                  red_margin={n: v[k:k + 1] for n, v in run.red_margins.items()},
                  stop_margin={n: v[k:k + 1] for n, v in run.sign_margins.items()},
                  object_count=np.array([float(run.stack.objects_seen)]),  # (as `outputs` records it at k)
                  road_edge={n: v[k:k + 1] for n, v in run.edges.items()},
                  road_end={n: v[k:k + 1] for n, v in run.ends.items()},
                  variables={n: v[k:k + 1] for n, v in run.variable_records.items()},
                  wrong_way={n: v[k:k + 1] for n, v in run.wrong_ways.items()},
                  off_lanes={n: v[k:k + 1] for n, v in run.offs.items()})
    if run.lane_ids:  # `lane_id(A)` reads the lanes now
        trace.lanes = {name: np.array([run.lane_number(name)]) for name in rec}
    if run.named_steps and with_steps:  # `when ended(lead.brake_hard)` reads the states now
        trace.steps = {name: np.array([code], dtype=np.int8) for name, code in run.step_states(t).items()}
    return trace
