"""Candidates of the search are *pinned* RunSpecs (`printer.pin_spec`): parameters fixed,
concrete faults with their seeds, no sweep. Edits rebuild the plan and the RunSpec
together, so a candidate is always exactly what its printed `.addt` file replays.

Each fault keeps its own seed through every edit, so deleting one fault does not
reshuffle the random streams of the others.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from addt_dsl import expr as E
from addt_dsl.plan import ConcreteFault, RunSpec, ScenarioPlan
from addt_dsl.printer import params_referenced, pin_spec, pinned_fault_plan
from addt_dsl.registry import FAULTS


@dataclass(frozen=True)
class FaultEntry:
    fault: ConcreteFault
    label: str  # where it came from (`file:line`, or `fault #i`): stable across edits


def pinned(spec: RunSpec) -> RunSpec:
    """Pin `spec` and give every fault a unique, stable label (its source line)."""
    spec = pin_spec(spec)
    labels, seen = [], set()
    for f, fp in zip(spec.faults, spec.plan.faults):
        label = fp.source or f"fault #{f.index}"
        if label in seen:
            label = f"{label}#{f.index}"
        seen.add(label)
        labels.append(label)
    return rebuild(spec, faults=[FaultEntry(f, lab) for f, lab in zip(spec.faults, labels)])


def entries(spec: RunSpec) -> list[FaultEntry]:
    return [FaultEntry(f, fp.source) for f, fp in zip(spec.faults, spec.plan.faults)]


def rebuild(spec: RunSpec, *, params: dict[str, float] | None = None, faults: list[FaultEntry] | None = None,
            plan_updates: dict | None = None) -> RunSpec:
    """A pinned RunSpec with some parts replaced; the plan follows the RunSpec."""
    params = dict(spec.params) if params is None else dict(params)
    faults = entries(spec) if faults is None else faults
    concrete = [e.fault.model_copy(update={"index": i}) for i, e in enumerate(faults)]
    plan: ScenarioPlan = spec.plan.model_copy(update=plan_updates or {})
    plan = plan.model_copy(update={
        "params": [p.model_copy(update={"default": params[p.name]}) for p in plan.params],
        "faults": [pinned_fault_plan(f, e.label) for f, e in zip(concrete, faults)],
    })
    return RunSpec(plan=plan, params=params, seed=spec.seed, faults=concrete, run_id=spec.run_id)


def with_fault(spec: RunSpec, index: int, **changes) -> RunSpec:
    """Change one fault: `start_s`, `end_s`, or `settings` (a full dict)."""
    es = entries(spec)
    e = es[index]
    es[index] = FaultEntry(e.fault.model_copy(update=changes), e.label)
    return rebuild(spec, faults=es)


def without_faults(spec: RunSpec, indices) -> RunSpec:
    drop = set(indices)
    return rebuild(spec, faults=[e for i, e in enumerate(entries(spec)) if i not in drop])


# ---------------------------------------------------------------- agents

def _signal_actors(expr) -> set[str]:
    out = set()
    for name in E.signals_used(expr):
        _, _, rest = name.partition("(")
        out |= {a for a in rest.rstrip(")").split(",") if a}
    return out


def removable_agents(spec: RunSpec, keep_oracle: str) -> list[str]:
    """Agents no trigger and not the kept oracle refer to (other oracles that do are
    dropped with the agent)."""
    plan = spec.plan
    pinned_names = set()
    for o in plan.oracles:
        if o.name == keep_oracle:
            pinned_names |= _signal_actors(o.formula)
    for a in plan.agents:
        for tr in a.triggers:
            pinned_names |= _signal_actors(tr.condition) - {a.name}
    return [a.name for a in plan.agents if a.name not in pinned_names]


def without_agents(spec: RunSpec, names) -> RunSpec:
    names = set(names)
    plan = spec.plan
    agents = [a for a in plan.agents if a.name not in names]
    oracles = [o for o in plan.oracles if not (_signal_actors(o.formula) & names)]
    out = rebuild(spec, plan_updates={"agents": agents, "oracles": oracles})
    return drop_unused_params(out)


def drop_unused_params(spec: RunSpec) -> RunSpec:
    used = params_referenced(spec.plan)
    if used >= set(spec.params):
        return spec
    plan = spec.plan.model_copy(update={"params": [p for p in spec.plan.params if p.name in used]})
    return rebuild(spec.model_copy(update={"plan": plan}), params={k: v for k, v in spec.params.items() if k in used})


# ---------------------------------------------------------------- measures

def neutral_value(kind: str, setting: str) -> float:
    """The value at which a fault setting does least: 0 clipped into its range
    (`slow factor` → 1, `count` → 1, `drop rate` → 0, `shift yaw` → 0)."""
    cls = FAULTS.get(kind)
    spec = next((p for p in cls.params if p.name == setting), None) if cls else None
    if spec is not None and spec.neutral is not None:
        return float(spec.neutral)
    lo = spec.low if spec is not None and spec.low is not None else -math.inf
    hi = spec.high if spec is not None and spec.high is not None else math.inf
    return min(max(0.0, lo), hi)


def drawn_setting(kind: str) -> str | None:
    """The fault kind's setting drawn per injection and recorded (`FaultKind.drawn_setting`)."""
    cls = FAULTS.get(kind)
    return cls.drawn_setting if cls else None


def effective_settings(f: ConcreteFault) -> dict:
    """The settings the fault kind will use: the given ones, defaults for the rest (a
    setting left out is not smaller: `drop` without `rate` drops every frame)."""
    cls = FAULTS.get(f.kind)
    out = {p.name: float(p.default) if isinstance(p.default, (int, float)) else p.default
           for p in (cls.params if cls else ()) if p.default is not None}
    out.update(f.settings)
    return out


def window_length(f: ConcreteFault, duration_s: float) -> float:
    end = duration_s if f.end_s is None else min(f.end_s, duration_s)
    return max(0.0, end - f.start_s)


def _digits(x: float) -> int:
    text = repr(float(x))
    return len(text[:-2] if text.endswith(".0") else text)


def sort_key(spec: RunSpec, nominal: dict[str, float], scales: dict[str, float]) -> tuple:
    """Shortlex-style complexity: fewer faults, fewer agents, shorter run and windows,
    smaller magnitudes, lower bits, parameters nearer nominal, fewer settings, shorter
    numbers. The shrinker accepts a candidate only if this strictly decreases, so it
    always terminates."""
    plan = spec.plan
    magnitude = bits = 0.0
    n_settings = digits = 0
    for f in spec.faults:
        n_settings += len(f.settings)
        digits += _digits(f.start_s) + (_digits(f.end_s) if f.end_s is not None else 0)
        digits += sum(_digits(v) for v in f.settings.values() if isinstance(v, float))
        for k, v in effective_settings(f).items():
            if not isinstance(v, float):
                continue
            if k == drawn_setting(f.kind):
                bits += 64.0 if v < 0 else v  # a drawn value is the most complex choice
            else:
                magnitude += abs(v - neutral_value(f.kind, k))
    params = 0.0
    for k, v in spec.params.items():
        digits += _digits(v)
        params += abs(v - nominal.get(k, v)) / scales.get(k, 1.0)
    window = sum(window_length(f, plan.duration_s) for f in spec.faults)
    return (len(spec.faults), len(plan.agents), round(plan.duration_s, 9), round(window, 9), round(magnitude, 12),
            bits, round(params, 12), n_settings, digits)
