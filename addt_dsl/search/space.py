"""The search space of `addtc falsify`: a unit hypercube whose points are RunSpecs.

Its axes: every parameter with a range or choices (grid values count as choices); per
declared fault, whether it is present, its start time and window length, and each
constant numeric setting (from its neutral value to twice the declared one, inside the
registry's range; counts from 1), plus the bit for bit flips with a fixed bit. Settings
written with a parameter move with that parameter. Fault seeds and the run seed are
drawn afresh for every candidate (`SearchSpace.spec`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from addt_dsl import expr as E
from addt_dsl.plan import RunSpec, ScenarioPlan
from addt_dsl.registry import FAULTS
from addt_dsl.search import candidates as C
from addt_dsl.sweep import concrete_faults, derive_seed, from_unit

@dataclass(frozen=True)
class Axis:
    name: str  # `param:gap`, `fault3:present`, `fault3:start`, `fault3:length`, `fault3:value`, ...
    kind: str  # "unit" (continuous) | "bool"
    decode: object = None  # callable(u) -> value (for reporting)
    # A fault axis's most severe end (present, from the start, for the whole run, the
    # setting farthest from neutral); None: no severe end (parameters, drawn bits, instants).
    severe: float | None = None


class SearchSpace:
    def __init__(self, plan: ScenarioPlan):
        self.plan = plan
        self.nominal = plan.nominal_params()
        self.axes: list[Axis] = []
        grid = {g.param: g.values for g in plan.sweep.grid}
        self.params = []
        for p in plan.params:
            choices = list(p.choices) or (grid.get(p.name) if (p.low is None or p.high is None) else None)
            if choices and len(set(choices)) > 1:
                self.params.append((p, choices))
            elif p.low is not None and p.high is not None and p.low < p.high:
                self.params.append((p, None))
            else:
                continue
            self.axes.append(Axis(f"param:{p.name}", "unit"))
        nominal_faults = concrete_faults(plan, self.nominal, plan.seed)
        self.faults = []  # (index, concrete at nominal, [(setting, lo, hi, integer)], instant, fixed_length)
        for f, fp in zip(nominal_faults, plan.faults):
            cls = FAULTS.get(f.kind)
            specs = {s.name: s for s in cls.params}
            settings = []
            severe: dict[str, float] = {}  # setting -> its unit value farthest from neutral
            for name, value in f.settings.items():
                spec = specs.get(name)
                expr = fp.settings.get(name)
                if spec is None or not isinstance(value, float) or isinstance(expr, (str, list)):
                    continue
                if expr is not None and E.params_used(expr):
                    continue  # moves with its parameter
                if name == C.drawn_setting(f.kind):
                    if value >= 0:
                        settings.append((name, 0.0, 63.0, True))
                    continue
                neutral = C.neutral_value(f.kind, name)
                lo, hi = sorted((neutral, neutral + 2.0 * (value - neutral)))
                lo = max(lo, spec.low) if spec.low is not None else lo
                hi = min(hi, spec.high) if spec.high is not None else hi
                if spec.kind == "int":
                    lo = max(lo, 1.0)
                if hi > lo:
                    settings.append((name, lo, hi, spec.kind == "int"))
                    severe[name] = 1.0 if abs(hi - neutral) >= abs(lo - neutral) else 0.0
            # A window a condition opens (`when C for W`) stays where its condition puts it.
            timed = fp.opens is None and not E.params_used(fp.start_s) and (
                fp.end_s is None or not E.params_used(fp.end_s))
            instant = f.end_s is not None and f.end_s == f.start_s
            self.faults.append((f.index, f, settings, instant, timed))
            self.axes.append(Axis(f"fault{f.index}:present", "bool", severe=1.0))
            if timed:
                # an instant fault has no worst time; a window's worst is the whole run
                self.axes.append(Axis(f"fault{f.index}:start", "unit", severe=None if instant else 0.0))
                if not instant:
                    self.axes.append(Axis(f"fault{f.index}:length", "unit", severe=1.0))
            for name, *_ in settings:
                self.axes.append(Axis(f"fault{f.index}:{name}", "unit", severe=severe.get(name)))
        self.index = {a.name: i for i, a in enumerate(self.axes)}

    @property
    def dims(self) -> int:
        return len(self.axes)

    def params_of(self, u: np.ndarray) -> dict[str, float]:
        params = dict(self.nominal)
        for p, choices in self.params:
            x = float(u[self.index[f"param:{p.name}"]])
            if choices:
                params[p.name] = choices[min(int(x * len(choices)), len(choices) - 1)]
            else:
                params[p.name] = from_unit(p, x)
        return params

    def spec(self, u: np.ndarray, seed: int, run_id: str) -> RunSpec:
        """The pinned RunSpec of point `u`; `seed` gives the run seed and the fault seeds."""
        plan = self.plan
        params = self.params_of(u)
        run_seed = derive_seed(seed, 1)
        nominal = {f.index: f for f in concrete_faults(plan, params, run_seed)}
        entries = []
        duration = plan.duration_s
        for index, _, settings, instant, timed in self.faults:
            if u[self.index[f"fault{index}:present"]] < 0.5:
                continue
            f = nominal[index]
            changes: dict = {"seed": derive_seed(seed, 2, index)}
            if timed:
                start = float(u[self.index[f"fault{index}:start"]]) * duration
                changes["start_s"] = start
                if instant:
                    changes["end_s"] = start
                else:
                    length = float(u[self.index[f"fault{index}:length"]]) * (duration - start)
                    changes["end_s"] = start + length
            new_settings = dict(f.settings)
            for name, lo, hi, integer in settings:
                x = lo + float(u[self.index[f"fault{index}:{name}"]]) * (hi - lo)
                new_settings[name] = float(round(x)) if integer else x
            changes["settings"] = new_settings
            entries.append(C.FaultEntry(f.model_copy(update=changes), plan.faults[index].source or f"fault #{index}"))
        base = RunSpec(plan=plan, params=params, seed=run_seed, faults=[], run_id=run_id)
        return C.rebuild(C.pinned(base), faults=entries)

