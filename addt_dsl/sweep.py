"""Plan → RunSpecs: grids, samplers (random; Halton and Latin hypercube from scipy.stats.qmc), repeats, seeds.

Seeds are derived from (plan seed, sweep seed, scenario instance, sample, repeat) with
numpy's SeedSequence, so a RunSpec's seed does not depend on how many runs come before it
or on the worker that executes it. The instance is the grid cell without its fault-only
axes: cells that differ only in what the faults read (`grid drop_rate in [1, 5] %`) run
the same scenarios, paired, and share one fault-free twin per run (`--classify`).
Assumptions reject samples (bounded, counted); they never fail a run.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from addt_dsl.distributions import from_unit
from addt_dsl.expr import Num, eval_param_expr, params_used, substitute_params
from addt_dsl.plan import ConcreteFault, FaultPlan, ParamPlan, RunSpec, ScenarioPlan, TriggerPlan, resolve_settings


SAMPLE_BATCH_VALUES = 1_000_000  # numbers drawn at once by a sampler (8 MB)


class UnsatisfiableAssumptions(ValueError):
    """No sample satisfied the assumptions within the resample cap."""


@dataclass
class Expansion:
    specs: list[RunSpec]
    rejected: Counter = field(default_factory=Counter)  # assumption text → rejected samples


def derive_seed(*parts: int) -> int:
    return int(np.random.SeedSequence([int(p) & 0xFFFFFFFF for p in parts]).generate_state(1)[0])


def concrete_faults(plan: ScenarioPlan, params: dict[str, float], run_seed: int) -> list[ConcreteFault]:
    return [concrete_fault(i, f, params, run_seed) for i, f in enumerate(plan.faults)]


def concrete_fault(index: int, f: FaultPlan, params: dict[str, float], run_seed: int) -> ConcreteFault:
    start = eval_param_expr(f.start_s, params)
    end = eval_param_expr(f.end_s, params) if f.end_s is not None else None
    seed = f.seed if f.seed is not None else derive_seed(run_seed, 7919, index)
    return ConcreteFault(index=index, kind=f.kind, target=f.target, start_s=start, end_s=end,
                         settings=resolve_settings(f.settings, params), seed=seed,
                         opens=_resolved_start(f.opens, params) if f.opens is not None else None)


def _resolved_start(t: TriggerPlan, params: dict[str, float]) -> TriggerPlan:
    """A step's start with its parameters substituted: the run's values, nothing left to bind."""
    times = {k: Num(value=eval_param_expr(getattr(t, k), params))
             for k in ("at_s", "after_s", "hold_s", "delay_s") if getattr(t, k) is not None}
    condition = substitute_params(t.condition, params) if t.condition is not None else None
    return t.model_copy(update={"condition": condition, **times})


def make_spec(plan: ScenarioPlan, params: dict[str, float], seed: int, run_id: str = "",
              cell: dict[str, float] | None = None, repeat_index: int = 0) -> RunSpec:
    return RunSpec(plan=plan, params=params, seed=seed, faults=concrete_faults(plan, params, seed),
                   run_id=run_id, cell=cell or {}, repeat_index=repeat_index)


def assumption_key(a) -> str:
    """How reports name a constraint: its label, else its source text."""
    return a.name or a.text


def violated_assumptions(plan: ScenarioPlan, params: dict[str, float]) -> list[str]:
    return [assumption_key(a) for a in plan.assumptions if not _holds(a.expr, params)]


def _holds(expr, params: dict[str, float]) -> bool:
    try:
        value = eval_param_expr(expr, params)
    except (ValueError, OverflowError, ZeroDivisionError):  # e.g. sqrt of a negative: not a valid sample
        return False
    return bool(value) and not math.isnan(value)


class _RandomEngine:
    """Plain uniform draws behind the `random(n)` interface of scipy's QMC engines."""

    def __init__(self, dims: int, rng: np.random.Generator):
        self.dims, self.rng = dims, rng

    def random(self, n: int) -> np.ndarray:
        return self.rng.random((n, self.dims))


def _unit_engine(kind: str, dims: int, seed: int):
    """An engine whose `random(n)` gives points in [0, 1)^dims, deterministic in `seed`.

    Halton is scrambled (scipy gives each axis its own prime base, so no two axes repeat
    however many parameters are sampled) and continues its sequence across calls, so a
    batch drawn after rejections stays low-discrepancy. Each Latin hypercube call is a
    fresh design: one point per stratum per axis among the `n` drawn."""
    rng = np.random.default_rng(seed)
    if kind == "random":
        return _RandomEngine(dims, rng)
    # scipy.stats costs ~0.6 s to import; only sweeps that sample pay it (not `addtc check`).
    from scipy.stats import qmc

    return {"halton": qmc.Halton, "lhs": qmc.LatinHypercube}[kind](dims, rng=rng)


def expand(plan: ScenarioPlan) -> Expansion:
    """All RunSpecs of the plan's sweep, in a stable order with stable ids (a list; see
    `SweepStream` for large sweeps)."""
    stream = SweepStream(plan)
    specs = list(stream)
    return Expansion(specs, stream.rejected)


class SweepStream:
    """The plan's RunSpecs, expanded lazily in the same order and with the same ids and
    seeds as `expand`. Every RunSpec shares the one plan object, so a coordinator can
    walk a 10,000-run sweep holding only the specs in flight. Iterating again
    re-expands from scratch (same specs); `rejected` counts the last iteration's
    assumption rejections; `len()` is exact and draws no samples.
    """

    def __init__(self, plan: ScenarioPlan):
        self.plan = plan
        self.rejected: Counter = Counter()

    def __len__(self) -> int:
        return count_runs(self.plan)

    def __iter__(self):
        self.rejected = Counter()
        produced = 0
        for spec in _iter_specs(self.plan, self.rejected):
            produced += 1
            yield spec
        if not produced and self.plan.assumptions:
            raise UnsatisfiableAssumptions(
                "every candidate run breaks an assumption: "
                + ", ".join(f"{t} ({n} rejected)" for t, n in self.rejected.most_common()))


def _grid_cells(plan: ScenarioPlan):
    """The grid's cells in order, one at a time (a 12-axis grid of 1e12 cells is never built)."""
    for combo in itertools.product(*_axes(plan)):
        yield {k: v for part in combo for k, v in part}


def _axes(plan: ScenarioPlan) -> list[list[tuple]]:
    """Each axis of the grid's product as its list of cell parts ((name, value) pairs):
    the `grid` axes, then the `cases` axes (one part per listed combination)."""
    return ([[((g.param, v),) for v in g.values] for g in plan.sweep.grid]
            + [[tuple(zip(c.params, row)) for row in c.rows] for c in plan.sweep.cases])


def axis_params(plan: ScenarioPlan) -> set[str]:
    """The parameters the grid's axes fix (`grid` and `cases`)."""
    return {g.param for g in plan.sweep.grid} | {n for c in plan.sweep.cases for n in c.params}


def _instances(plan: ScenarioPlan):
    """For each grid cell in order, the index of its scenario instance: the cell's place
    in the grid without the axes of fault-only parameters (`ScenarioPlan.fault_only_params`).
    Seeds and samples derive from it, so cells that differ only in their faults run the
    same scenarios (paired runs) and share their fault-free twins. Without such axes it
    is the cell index."""
    fault_only = plan.fault_only_params()
    axes = [([g.param], len(g.values)) for g in plan.sweep.grid] + [(c.params, len(c.rows)) for c in plan.sweep.cases]
    kept = [(k, size) for k, (names, size) in enumerate(axes) if not set(names) <= fault_only]
    for combo in itertools.product(*[range(size) for _, size in axes]):
        index = 0
        for k, size in kept:
            index = index * size + combo[k]
        yield index


def grid_cell_count(plan: ScenarioPlan) -> int:
    """Cells of the grid (1 without a grid), counted without building them."""
    return math.prod(len(g.values) for g in plan.sweep.grid) * math.prod(len(c.rows) for c in plan.sweep.cases)


def sampled_params(plan: ScenarioPlan) -> list[ParamPlan]:
    """The parameters the sampler draws (those with a range or choices that no grid fixes)."""
    return _sampled_params(plan, axis_params(plan))


def count_runs(plan: ScenarioPlan) -> int:
    """Number of RunSpecs the sweep expands to. Samplers always deliver `count` accepted
    samples per cell (or fail), so this needs no sampling; without a sampler, cells that
    break an assumption do not run, so each cell is checked (one at a time: check the
    estimate of addt_dsl/cost.py first for a huge grid)."""
    sweep = plan.sweep
    if sweep.sampler and sampled_params(plan):
        return grid_cell_count(plan) * sweep.sampler.count * sweep.repeat
    if not plan.assumptions:
        return grid_cell_count(plan) * sweep.repeat
    nominal = plan.nominal_params()
    valid = sum(1 for cell in _grid_cells(plan) if not violated_assumptions(plan, {**nominal, **cell}))
    return valid * sweep.repeat


def _iter_specs(plan: ScenarioPlan, rejected: Counter):
    sweep = plan.sweep
    nominal = plan.nominal_params()
    sampled = sampled_params(plan)
    for ci, (cell, instance) in enumerate(zip(_grid_cells(plan), _instances(plan))):
        base = {**nominal, **cell}
        if violated_assumptions(plan, base) and not (sweep.sampler and sampled):
            for text in violated_assumptions(plan, base):
                rejected[text] += 1
            continue
        if sweep.sampler and sampled:
            assignments = _sample_cell(plan, base, sampled, instance, rejected)
        else:
            assignments = iter([base])
        for si, params in enumerate(assignments):
            for r in range(sweep.repeat):
                seed = (plan.run_seed if plan.run_seed is not None
                        else derive_seed(plan.seed, sweep.seed, instance, si, r))
                run_id = f"c{ci:03d}" + (f"-s{si:04d}" if sweep.sampler else "") + f"-r{r:03d}"
                yield make_spec(plan, params, seed, run_id, cell, r)


def _sampled_params(plan: ScenarioPlan, gridded: set[str]) -> list[ParamPlan]:
    return [p for p in plan.params if p.name not in gridded
            and (p.low is not None and p.high is not None and p.low < p.high or p.choices)]


def known_assignments(plan: ScenarioPlan, names: set[str], max_cells: int) -> list[dict[str, float]] | None:
    """The distinct values the parameters `names` take over the sweep's runs, in grid order,
    when every run's are known before sampling: none of them is drawn by the sampler and the
    grid has at most `max_cells` cells (None otherwise). A cell that an assumption on known
    parameters rejects runs nothing and is left out. For checks at compile time."""
    sampled = {p.name for p in sampled_params(plan)} if plan.sweep.sampler else set()
    if names & sampled or grid_cell_count(plan) > max_cells:
        return None
    known = [a for a in plan.assumptions if not (params_used(a.expr) & sampled)]
    nominal = plan.nominal_params()
    out: dict[tuple, dict[str, float]] = {}
    for cell in _grid_cells(plan):
        base = {**nominal, **cell}
        if any(not _holds(a.expr, base) for a in known):
            continue
        values = {n: base[n] for n in sorted(names) if n in base}
        out.setdefault(tuple(values.values()), values)
    return list(out.values())


def probe_feasibility(plan: ScenarioPlan, budget: int = 2000) -> Counter | None:
    """Try up to `budget` candidate assignments the sweep could produce; None as soon as
    one satisfies every assumption, else the rejection counts (the scenario is
    unsatisfiable as far as the probe can tell). Cheap enough to run at compile time."""
    if not plan.assumptions:
        return None
    sweep = plan.sweep
    nominal = plan.nominal_params()
    sampled = _sampled_params(plan, axis_params(plan)) if sweep.sampler else []
    rejected: Counter = Counter()
    tried = 0
    n_cells = grid_cell_count(plan)
    per_cell = max(1, budget // max(1, min(n_cells, budget)))
    engine = _unit_engine(sweep.sampler.kind, len(sampled), derive_seed(plan.seed, 15485863)) if sampled else None
    for cell in itertools.islice(_grid_cells(plan), budget):
        base = {**nominal, **cell}
        if sampled:
            n = max(1, min(budget - tried, per_cell, SAMPLE_BATCH_VALUES // len(sampled)))
            rows = engine.random(n)
            candidates = ({**base, **{p.name: from_unit(p, float(u)) for p, u in zip(sampled, row)}}
                          for row in rows)  # lazy: most scenarios accept the first one
        else:
            candidates = iter([base])
        for params in candidates:
            tried += 1
            broken = violated_assumptions(plan, params)
            if not broken:
                return None
            rejected.update(broken)
        if tried >= budget:
            break
    return rejected


def _sample_cell(plan, base, sampled, instance, rejected):
    """Accepted parameter assignments of one cell, drawn lazily in batches."""
    sampler = plan.sweep.sampler
    engine = _unit_engine(sampler.kind, len(sampled), derive_seed(plan.seed, sampler.seed, instance, 104729))
    accepted = 0
    cap = plan.sweep.max_rejections
    while accepted < sampler.count:
        # In batches of at most SAMPLE_BATCH_VALUES numbers: 1e6 samples of 2,000 parameters
        # would otherwise be one 16 GB array. (A Latin hypercube larger than a batch is
        # drawn as consecutive hypercubes of one batch each.)
        need = min(sampler.count - accepted, max(1, SAMPLE_BATCH_VALUES // max(1, len(sampled))))
        for row in engine.random(need):
            params = {**base, **{p.name: from_unit(p, float(u)) for p, u in zip(sampled, row)}}
            broken = violated_assumptions(plan, params)
            if broken:
                for text in broken:
                    rejected[text] += 1
                if sum(rejected.values()) > cap:
                    raise UnsatisfiableAssumptions(
                        f"more than {cap} samples rejected: "
                        + ", ".join(f"{t} ({n})" for t, n in rejected.most_common()))
                continue
            accepted += 1
            yield params
