"""A logical scenario in: an OpenSCENARIO ParameterValueDistribution file and the template
it names -> one `.addt` whose `sweep` block is the distribution (docs/openscenario.md,
"Logical scenarios").

The template is imported by `import_xosc` with `_Template`, which keeps the varied
parameters where `${...}` arithmetic uses them (esmini's `${$EgoSpeed / 3.6}`: EgoSpeed in
km/h); parameters keep their names, each one's dimension is where the template uses it.
Then, exactly or not at all:

- Deterministic: `DistributionRange` and `DistributionSet` -> `grid` axes,
  `ValueSetDistribution` -> a `cases` axis (listed combinations); all multiplied, as
  OpenSCENARIO combines them.
- Stochastic (`numberOfTestRuns`, `randomSeed`) -> `random N seed S` over parameter
  domains: `UniformDistribution` -> `in [lo, hi]`, `NormalDistribution` -> `dist normal`
  (mean, sd = sqrt(variance), truncated to the range if given), `LogNormalDistribution`
  -> `dist lognormal` (its own mean and sd), `PoissonDistribution` -> `dist poisson`,
  `ProbabilityDistributionSet` -> a choice with `weights`, a `Histogram` -> `dist
  histogram` (bins and weights; uniform where the bins are even). A user-defined
  distribution is refused with a diagnostic saying so.
- `ValueConstraintGroup`s on the template's declarations of varied parameters ->
  `assume`s: combinations outside them are skipped and counted by the sweep.

A distribution that would make more runs than `Limits.runs` (docs/limits.md) is refused
(E0701) before any value list is built. Reading reuses the importer's safe XML reader and
parameter handling (`reader.Importer`).
"""

from __future__ import annotations

import ast
import json
import math
import re
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.compiler import compile_source
from addt_dsl.confine import Refused, confine
from addt_dsl.diagnostics import Span
from addt_dsl.interop.openscenario.conditions import RULE_OPS
from addt_dsl.interop.openscenario.distribution_export import PARAMETRIC_KEY
from addt_dsl.interop.openscenario.importer import DOCUMENT_KINDS, Imported, Translate, import_xosc
from addt_dsl.interop.openscenario.params import arith
from addt_dsl.interop.openscenario.reader import Importer
from addt_dsl.interop.openscenario.registry import DISTRIBUTIONS
from addt_dsl.interop.openscenario.sidefile import SIDECAR_PARAM
from addt_dsl.interop.openscenario.xml import MAX_XML_BYTES, Stop
from addt_dsl.limits import DEFAULT, MAX_ABS_NUMBER, Limits
from addt_dsl.plan import AssumptionPlan, CaseAxis, GridAxis, ParamPlan, SamplerPlan, ScenarioPlan, SweepPlan
from addt_dsl.printer import PrinterError, print_plan, side_files
from addt_dsl.distributions import MAX_POISSON_MEAN, lognormal_mu_sigma
from addt_dsl.sweep import count_runs, grid_cell_count

NUMERIC_TYPES = ("double", "integer", "int", "unsignedInt", "unsignedShort")
INTEGER_TYPES = ("integer", "int", "unsignedInt", "unsignedShort")
# A NormalDistribution without a range gets mean +- this many sd: the sampler's inverse CDF
# is clipped at u in [1e-12, 1 - 1e-12] (+-7.03 sd), so such a range never binds.
NORMAL_UNBOUNDED_SD = 8.0
MAX_SEED = 2**31 - 1
NOT_DRAWN = {
    "UserDefinedDistribution": "a user-defined distribution has no definition a player can share",
}


def names_distribution(path: str | Path) -> bool:
    """Whether the file reads as a ParameterValueDistribution (a cheap look at its bytes; the
    full, safe parse follows in `import_distribution`). A scenario has a Storyboard, which
    a distribution file cannot have."""
    try:
        with open(path, "rb") as f:
            head = f.read(MAX_XML_BYTES + 1)
    except OSError:
        return False
    return b"<ParameterValueDistribution" in head and b"<Storyboard" not in head


def import_distribution(path: str | Path, root: str | Path | None = None, maps=(),
                        limits: Limits = DEFAULT, lenient: bool = False, ego: str = "stack") -> Imported:
    """Translate a ParameterValueDistribution and its template into one `.addt` with a sweep
    (`lenient` and `ego` are the template's import's, as for `import_xosc`)."""
    path = Path(path)
    imp = _Distribution(path, Path(root) if root is not None else path.parent, tuple(Path(m) for m in maps), limits)
    imp.template_options = {"lenient": lenient, "ego": ego}
    if not path.resolve().is_relative_to(imp.root):
        imp.sink.error("E0402", f"{path} is outside the root directory", None)
        return Imported(None, None, imp.sink.items, imp.sources)
    try:
        got = imp.run()
    except Stop:
        got = None
    except RecursionError:
        imp.sink.error("E0801", "the document is nested too deeply", Span.point(imp.display, 1, 1))
        got = None
    if got is None or imp.sink.has_errors:
        return Imported(None, None, imp.sink.items, imp.sources)
    return got


class _Distribution(Importer):
    def __init__(self, path: Path, root: Path, maps: tuple[Path, ...], limits: Limits):
        super().__init__(path, root, maps)
        self.limits = limits
        self.used: dict[str, object] = {}  # parameter -> the element that varies it
        self.template: Importer | None = None  # the template, read again for its declarations
        self.decls: dict[str, object] = {}  # template parameter -> its <ParameterDeclaration>
        self.from_side_file = False  # the parameters come from the side file of `addtc export --sweep`
        self.scales: dict[str, float] = {}  # the template's parameter scales (_Template)
        self.template_options: dict = {}  # import_xosc's lenient and ego, for the template

    def run(self) -> Imported | None:
        got = self.read(self.path.name, self.path.parent, None)
        if got is None:
            return None
        self.sources[self.display] = got[1]
        doc = self.parse(got[1], self.display)
        if doc is None:
            return None
        if doc.tag != "OpenSCENARIO":
            self.error(doc, f"the root element is <{doc.tag}>, not <OpenSCENARIO>")
            return None
        pvd = doc.find("ParameterValueDistribution")
        if pvd is None:
            self.error(doc, "no <ParameterValueDistribution>: not a logical scenario")
            return None
        tmpl = self.import_template(pvd)
        plan = tmpl.plan
        params = {p.name: p for p in plan.params}
        det, sto = pvd.find("Deterministic"), pvd.find("Stochastic")
        grid: list[GridAxis] = []
        cases: list[CaseAxis] = []
        sampler = None
        if det is not None:
            grid, cases = self.deterministic(det, params)
        elif sto is not None:
            sampler = self.stochastic(sto, params)
        else:
            self.error(pvd, "<ParameterValueDistribution> has neither <Deterministic> nor <Stochastic>")
            raise Stop
        if self.sink.has_errors:
            return None
        assumptions = self.constraints(params)
        if self.sink.has_errors:
            return None
        plan = plan.model_copy(update={
            "params": [params[p.name] for p in plan.params], "assumptions": [*plan.assumptions, *assumptions],
            "sweep": SweepPlan(grid=grid, cases=cases, sampler=sampler)})
        return self.finish(pvd, plan, tmpl, assumptions)

    # -- the template

    def import_template(self, pvd) -> Imported:
        sf = pvd.find("ScenarioFile")
        if sf is None:
            self.error(pvd, "<ParameterValueDistribution> has no <ScenarioFile>")
            raise Stop
        relative = self.raw(sf, "filepath")
        try:
            path = confine(relative, self.path.parent, self.root)
        except Refused as refused:
            self.sink.error(refused.code, refused.message, self.span(sf), *([refused.note] if refused.note else []),
                            label="<ScenarioFile>")
            raise Stop from None
        if names_distribution(path):  # itself, or a chain of distributions: never followed
            self.error(sf, f"{relative} is a ParameterValueDistribution, not a scenario")
            raise Stop
        made: list[_Template] = []
        varied = frozenset(self.named(pvd))

        def translator(*args, **options):
            made.append(_Template(*args, **options))
            made[-1].varied = varied
            return made[-1]

        tmpl = import_xosc(path, self.root, self.maps, translator=translator, **self.template_options)
        self.scales = made[0].scales if made else {}
        self.sink.items.extend(tmpl.diagnostics)
        self.sources.update(tmpl.sources)
        if tmpl.plan is None:
            self.error(sf, f"the scenario {relative} does not import (see its diagnostics)")
            raise Stop
        if tmpl.plan.sweep != SweepPlan() or any(p.low is not None or p.choices for p in tmpl.plan.params):
            self.error(sf, f"the scenario {relative} already has a sweep (its addt-dsl side file): "
                           "a distribution of it would be a second one")
            raise Stop
        # The template once more, for its declarations (types, constraint groups); the
        # importer has read it without errors, so this parse succeeds.
        self.template = Importer(path, self.root)
        got = self.template.read(path.name, path.parent, None)
        doc = self.template.parse(got[1], self.template.display) if got is not None else None
        if doc is None:
            self.sink.items.extend(self.template.sink.items)
            raise Stop
        for decl in [*doc.iterfind("ParameterDeclarations/ParameterDeclaration"),
                     *doc.iterfind("Storyboard//ParameterDeclaration")]:
            name = decl.get("name")
            if name and name not in self.decls:
                self.decls[name] = decl
                self.template.params[name] = (decl.get("parameterType", "string"), decl.get("value", ""))
        parametric = self.parametric(doc, path)
        if parametric is not None:  # its parameters: those the fault schedule reads are not in the OpenSCENARIO
            self.from_side_file = True
            return Imported(tmpl.text, parametric, [], {}, tmpl.side_files, tmpl.entities)
        return tmpl

    def parametric(self, doc, path: Path) -> ScenarioPlan | None:
        """The scenario with its parameters from the side file of `addtc export --sweep`
        (the template's OpenSCENARIO holds one run's numbers), its domains and sweep
        cleared for the distribution's; None without one."""
        t = self.template
        if SIDECAR_PARAM not in t.params:
            return None
        decls = doc.find("ParameterDeclarations")
        got = t.read(t.params[SIDECAR_PARAM][1], path.parent, decls)
        if got is None:  # the template's import has said why
            t.sink.items.clear()
            return None
        try:
            data = json.loads(got[1])
            raw = data.get(PARAMETRIC_KEY) if isinstance(data, dict) else None
            if raw is None:
                return None
            plan = ScenarioPlan.model_validate(raw)
        except (ValueError, TypeError, RecursionError) as exc:
            self.error(None, f"the side file {t.params[SIDECAR_PARAM][1]} of {path.name} has no valid "
                             f"'{PARAMETRIC_KEY}': {str(exc).splitlines()[0][:200]}")
            raise Stop from None
        if plan.name != data.get("scenario"):
            self.error(None, f"the side file {t.params[SIDECAR_PARAM][1]} describes scenario {plan.name!r}, "
                             f"not {data.get('scenario')!r}")
            raise Stop
        self.sink.warning("W0802", f"the parameters of {path.name} and where they are used come from its addt-dsl "
                          f"side file {t.params[SIDECAR_PARAM][1]} (the OpenSCENARIO holds one run's numbers)",
                          self.span(None), label="")
        params = [ParamPlan(name=p.name, dimension=p.dimension, default=p.default, integer=p.integer)
                  for p in plan.params]
        return plan.model_copy(update={"params": params, "sweep": SweepPlan()})

    def named(self, pvd) -> set[str]:
        """The parameter names the distribution varies (as written; checked later)."""
        return {v for el in pvd.iter() for k, v in el.attrib.items() if k in ("parameterName", "parameterRef")}

    # -- parameters

    def scale(self, name: str) -> float:
        """SI per unit of the parameter's values in the files (1 but for `${$P / 3.6}`)."""
        return self.scales.get(name, 1.0)

    def param(self, el, attr: str, params: dict[str, ParamPlan]) -> ParamPlan:
        """The template's parameter that `el` varies (refused: undeclared, not a number, not
        read by the translated scenario, or varied twice)."""
        name = self.raw(el, attr)
        decl = self.decls.get(name)
        if decl is None and self.from_side_file and name in params:
            decl = self.decls[name] = ET.Element("ParameterDeclaration", name=name, parameterType="double")
        if decl is None:
            self.error(el, f"the scenario declares no parameter '{name}'",
                       f"its parameters: {', '.join(self.decls) or 'none'}")
            raise Stop
        kind = decl.get("parameterType", "string")
        if kind not in NUMERIC_TYPES:
            self.error(el, f"parameter '{name}' is a {kind}: only numbers are swept")
            raise Stop
        if name not in params:
            self.error(el, f"the translated scenario does not read parameter '{name}' as a value (it is used "
                           "inside a ${...} expression, as text, or not at all): a sweep over it would not vary "
                           "the runs")
            raise Stop
        if name in self.used:
            self.error(el, f"parameter '{name}' is varied twice",
                       f"first at line {self.lines.get(id(self.used[name]), 1)}")
            raise Stop
        self.used[name] = el
        return params[name]

    def is_integer(self, name: str) -> bool:
        return self.decls[name].get("parameterType") in INTEGER_TYPES

    def values_of(self, el, name: str, texts: list[str]) -> list[float]:
        out = []
        for text in texts:
            try:
                v = float(self.resolve(text))
            except (KeyError, SyntaxError, ValueError, ArithmeticError, RecursionError, MemoryError):
                self.error(el, f"value \"{text[:40]}\" of '{name}' is not a number")
                raise Stop from None
            out.append(self.checked(el, name, v))
        return out

    def checked(self, el, name: str, v: float) -> float:
        if not math.isfinite(v) or abs(v) > MAX_ABS_NUMBER:
            self.error(el, f"value {v!r} of '{name}' is beyond {MAX_ABS_NUMBER:g} (docs/limits.md)")
            raise Stop
        if self.is_integer(name) and v != int(v):
            self.error(el, f"'{name}' is an {self.decls[name].get('parameterType')} parameter; {v!r} is not whole")
            raise Stop
        return v * self.scale(name)

    def num(self, el, attr: str) -> float:
        v = self.value(el, attr)
        if abs(v) > MAX_ABS_NUMBER:
            self.error(el, f"{attr}={v!r} is beyond {MAX_ABS_NUMBER:g} (docs/limits.md)")
            raise Stop
        return v

    def range_of(self, el, name: str, scaled: bool = True) -> tuple[float, float]:
        rng = el.find("Range")
        if rng is None:
            self.error(el, f"<{el.tag}> has no <Range>")
            raise Stop
        lo, hi = self.num(rng, "lowerLimit"), self.num(rng, "upperLimit")
        if lo > hi:
            self.error(rng, f"the range of '{name}' is empty: lowerLimit {lo!r} > upperLimit {hi!r}")
            raise Stop
        k = self.scale(name) if scaled else 1.0
        return lo * k, hi * k

    # -- deterministic

    def deterministic(self, det, params: dict[str, ParamPlan]) -> tuple[list[GridAxis], list[CaseAxis]]:
        """Grid axes and value sets, counted before any value list is built."""
        parts, runs = [], 1
        for el in det:
            if el.tag == "DeterministicSingleParameterDistribution":
                p = self.param(el, "parameterName", params)
                kind = _only(el)
                if kind is not None and kind.tag == "DistributionRange":
                    step = self.num(kind, "stepWidth")
                    lo, hi = self.range_of(kind, p.name, scaled=False)
                    if not step > 0:
                        self.error(kind, f"stepWidth of '{p.name}' must be positive, not {step!r}")
                        raise Stop
                    size = math.floor((hi - lo) / step + 1e-9) + 1
                    parts.append(("range", p, kind, (lo, step, size, hi)))
                elif kind is not None and kind.tag == "DistributionSet":
                    texts = [self.raw(e, "value") for e in kind.iterfind("Element")]
                    if not texts:
                        self.error(kind, "<DistributionSet> has no <Element>")
                        raise Stop
                    size = len(texts)
                    parts.append(("set", p, kind, texts))
                else:
                    self.refuse_kind(el, kind)
            elif el.tag == "DeterministicMultiParameterDistribution":
                vsd = el.find("ValueSetDistribution")
                sets = list(vsd.iterfind("ParameterValueSet")) if vsd is not None else []
                if not sets:
                    self.error(el, "<DeterministicMultiParameterDistribution> has no <ValueSetDistribution> "
                                   "with a <ParameterValueSet>")
                    raise Stop
                size = len(sets)
                parts.append(("sets", None, el, sets))
            else:
                self.skip(el, f"<{el.tag}> is not a deterministic distribution: ignored")
                continue
            runs *= size
            if runs > self.limits.runs:
                self.error(el, f"the distribution makes more than {self.limits.runs:,} runs (limit `runs`, "
                               "docs/limits.md); nothing was run",
                           "fewer values (a larger stepWidth, fewer elements) make fewer runs", code="E0701")
                raise Stop
        grid, cases = [], []
        for how, p, el, data in parts:
            if how == "range":
                lo, step, size, hi = data  # in the file's unit; `checked` makes them SI
                vals = [self.checked(el, p.name, min(lo + k * step, hi)) for k in range(size)]
                grid.append(GridAxis(param=p.name, values=vals))
                self.widen(params, p, vals)
            elif how == "set":
                vals = self.values_of(el, p.name, data)
                grid.append(GridAxis(param=p.name, values=vals))
                self.widen(params, p, vals)
            else:
                cases.append(self.value_sets(data, params))
        return grid, cases

    def value_sets(self, sets, params: dict[str, ParamPlan]) -> CaseAxis:
        """Listed combinations; a parameter a set leaves out keeps its declared value there."""
        names: list[str] = []
        rows: list[dict[str, float]] = []
        for s in sets:
            row = {}
            for a in s.iterfind("ParameterAssignment"):
                ref = a.get("parameterRef")
                if ref is not None and ref in row:
                    self.error(a, f"parameter '{ref}' is assigned twice in one <ParameterValueSet>")
                    raise Stop
                if ref not in names:
                    self.param(a, "parameterRef", params)
                    names.append(ref)
                row[ref] = self.values_of(a, ref, [self.raw(a, "value")])[0]
            if not row:
                self.error(s, "<ParameterValueSet> assigns no parameter")
                raise Stop
            rows.append(row)
        table = [[row.get(n, params[n].default) for n in names] for row in rows]
        for k, n in enumerate(names):
            self.widen(params, params[n], [r[k] for r in table])
        return CaseAxis(params=names, rows=table)

    def widen(self, params: dict[str, ParamPlan], p: ParamPlan, vals: list[float]) -> None:
        """The parameter's range: its values and its default (the compiler checks every value
        that depends on it over this range)."""
        lo, hi = min(vals + [p.default]), max(vals + [p.default])
        if lo < hi:
            params[p.name] = p.model_copy(update={"low": lo, "high": hi,
                                                  "integer": p.integer or self.is_integer(p.name)})

    def refuse_kind(self, el, kind) -> None:
        tag = kind.tag if kind is not None else "nothing"
        self.error(_first_of(kind, el), f"<{tag}> is not translated: "
                   + NOT_DRAWN.get(tag, "not a distribution of OpenSCENARIO 1.2/1.3"))
        raise Stop

    # -- stochastic

    def stochastic(self, sto, params: dict[str, ParamPlan]) -> SamplerPlan:
        runs = self.value(sto, "numberOfTestRuns")
        cap = min(self.limits.runs, 1_000_000)
        if runs != int(runs) or runs < 1:
            self.error(sto, f"numberOfTestRuns={runs!r} is not a whole number of at least 1")
            raise Stop
        if runs > cap:
            self.error(sto, f"numberOfTestRuns={int(runs):,} is more than {cap:,} runs (limit `runs`, "
                            "docs/limits.md; a sampler draws at most 1,000,000); nothing was run", code="E0701")
            raise Stop
        seed = self.value(sto, "randomSeed", default=0.0)
        if sto.get("randomSeed") is None:
            self.approx(sto, "no randomSeed: seed 0 (the runs are reproducible; OpenSCENARIO leaves the seed "
                             "to the player)")
        elif seed != int(seed) or not 0 <= seed <= MAX_SEED:
            self.error(sto, f"randomSeed={seed!r} is not a whole number in [0, {MAX_SEED}] (the language's seeds are)")
            raise Stop
        dists = list(sto.iterfind("StochasticDistribution"))
        if not dists:
            self.error(sto, "<Stochastic> has no <StochasticDistribution>")
            raise Stop
        for el in dists:
            p = self.param(el, "parameterName", params)
            kind = _only(el)
            draw = DISTRIBUTIONS.translator(kind.tag if kind is not None else "")
            if draw is None:
                self.refuse_kind(el, kind)
            if self.is_integer(p.name) and kind.tag not in ("ProbabilityDistributionSet", "PoissonDistribution"):
                self.error(kind, f"'{p.name}' is an {self.decls[p.name].get('parameterType')} parameter and "
                                 f"<{kind.tag}> draws fractions: the language's samplers do not round")
                raise Stop
            params[p.name] = draw(self, kind, p)
        return SamplerPlan(kind="random", count=int(runs), seed=int(seed))

    @DISTRIBUTIONS.register("UniformDistribution", "exact", "`in [lo, hi]` (the range)")
    def uniform(self, el, p: ParamPlan) -> ParamPlan:
        lo, hi = self.range_of(el, p.name)
        return _domain(p, lo, hi, distribution="uniform")

    @DISTRIBUTIONS.register("NormalDistribution", "exact", "`dist normal mean M sd sqrt(variance)`, truncated to "
                            "the range (without one: mean +- 8 sd)")
    def normal(self, el, p: ParamPlan) -> ParamPlan:
        mean, sd = self.mean_sd(el, p)
        lo, hi = self.range_of(el, p.name) if el.find("Range") is not None else \
            (mean - NORMAL_UNBOUNDED_SD * sd, mean + NORMAL_UNBOUNDED_SD * sd)
        if sd == 0 or lo == hi:
            return p.model_copy(update={"default": min(max(mean, lo), hi)})
        return _domain(p, lo, hi, distribution="normal", mean=mean, sd=sd)

    def mean_sd(self, el, p: ParamPlan) -> tuple[float, float]:
        mean, var = self.num(el, "expectedValue"), self.num(el, "variance")
        if var < 0:
            self.error(el, f"variance of '{p.name}' is negative ({var!r})")
            raise Stop
        return mean * self.scale(p.name), math.sqrt(var) * self.scale(p.name)

    @DISTRIBUTIONS.register("LogNormalDistribution", "exact", "`dist lognormal mean M sd S`: expectedValue and "
                            "variance read as the log-normal's own; truncated to the range")
    def lognormal(self, el, p: ParamPlan) -> ParamPlan:
        """expectedValue and variance are the log-normal's own (the standard's names), not
        its logarithm's; a range truncates it."""
        mean, sd = self.mean_sd(el, p)
        if not mean > 0:
            self.error(el, f"expectedValue of the log-normal '{p.name}' must be positive ({mean!r})")
            raise Stop
        if el.find("Range") is not None:
            lo, hi = self.range_of(el, p.name)
        else:
            mu, sigma = lognormal_mu_sigma(mean, sd) if sd > 0 else (math.log(mean), 0.0)
            lo, hi = math.exp(mu - NORMAL_UNBOUNDED_SD * sigma), math.exp(mu + NORMAL_UNBOUNDED_SD * sigma)
        if sd == 0 or lo == hi:
            return p.model_copy(update={"default": min(max(mean, lo), hi)})
        return _domain(p, lo, hi, distribution="lognormal", mean=mean, sd=sd)

    @DISTRIBUTIONS.register("PoissonDistribution", "exact", "`dist poisson mean L` on a dimensionless parameter; a "
                            "parameter with a unit is refused")
    def poisson(self, el, p: ParamPlan) -> ParamPlan:
        if p.dimension != "dimensionless":
            self.error(el, f"a Poisson distribution counts: '{p.name}' is used as a {p.dimension}")
            raise Stop
        lam = self.num(el, "expectedValue")
        if not 0 < lam <= MAX_POISSON_MEAN:
            self.error(el, f"expectedValue of the Poisson '{p.name}' must lie in (0, {MAX_POISSON_MEAN:g}] ({lam!r})")
            raise Stop
        if el.find("Range") is not None:
            lo, hi = self.range_of(el, p.name)
            lo, hi = float(max(0, math.ceil(lo))), float(math.floor(hi))
            if lo > hi:
                self.error(el, f"the range of the Poisson '{p.name}' holds no whole number")
                raise Stop
        else:  # beyond mean + 40 sd + 40 the mass is below double precision
            lo, hi = 0.0, float(math.ceil(lam + 40.0 * math.sqrt(lam) + 40.0))
        shaped = _domain(p, lo, hi, distribution="poisson", mean=lam, integer=True)
        return shaped.model_copy(update={"default": float(min(max(round(shaped.default), lo), hi))})

    @DISTRIBUTIONS.register("ProbabilityDistributionSet", "exact", "a choice with `weights [...]`")
    def probability_set(self, el, p: ParamPlan) -> ParamPlan:
        elements = list(el.iterfind("Element"))
        if not elements:
            self.error(el, "<ProbabilityDistributionSet> has no <Element>")
            raise Stop
        values = self.values_of(el, p.name, [self.raw(e, "value") for e in elements])
        weights = [self.weight(e, p) for e in elements]
        if not sum(weights) > 0:
            self.error(el, f"the weights of '{p.name}' are all zero")
            raise Stop
        if len(set(values)) == 1:
            return p.model_copy(update={"default": values[0]})
        default = p.default if p.default in values else values[0]
        uniform = len(set(weights)) == 1
        return p.model_copy(update={"default": default, "choices": values, "distribution": "choice",
                                    "weights": [] if uniform else weights, "integer": self.is_integer(p.name),
                                    "low": min(values), "high": max(values)})

    def weight(self, e, p: ParamPlan) -> float:
        w = self.num(e, "weight")
        if not 0 <= w <= MAX_ABS_NUMBER:
            self.error(e, f"weight {w!r} of '{p.name}' must be a number in [0, {MAX_ABS_NUMBER:g}]")
            raise Stop
        return w

    @DISTRIBUTIONS.register("Histogram", "exact", "`dist histogram bins [...] weights [...]` (gaps: bins of weight "
                            "0); overlapping bins are refused")
    def histogram(self, el, p: ParamPlan) -> ParamPlan:
        """Bins as a piecewise-uniform density; gaps between bins have none (a zero-weight bin)."""
        bins = []
        for b in el.iterfind("Bin"):
            lo, hi = self.range_of(b, p.name)
            bins.append((lo, hi, self.weight(b, p)))
        if not bins:
            self.error(el, "<Histogram> has no <Bin>")
            raise Stop
        bins.sort(key=lambda b: b[0])
        if any(b[0] < a[1] for a, b in zip(bins, bins[1:])) or any(hi <= lo for lo, hi, _ in bins):
            self.error(el, f"the bins of '{p.name}' overlap or are empty")
            raise Stop
        edges, weights = [bins[0][0]], []
        for lo, hi, w in bins:
            if lo > edges[-1]:  # a gap: a bin of no weight
                edges.append(lo)
                weights.append(0.0)
            edges.append(hi)
            weights.append(w)
        if not sum(weights) > 0:
            self.error(el, f"the weights of '{p.name}' are all zero")
            raise Stop
        if len(set(weights)) == 1 and len(weights) == len(bins):  # contiguous, even weights: uniform
            widths = {round((b - a) / (edges[-1] - edges[0]), 12) for a, b in zip(edges, edges[1:])}
            if len(widths) == 1:
                return _domain(p, edges[0], edges[-1], distribution="uniform")
        return _domain(p, edges[0], edges[-1], distribution="histogram", bins=edges, weights=weights)

    # -- constraints

    def constraints(self, params: dict[str, ParamPlan]) -> list[AssumptionPlan]:
        """ValueConstraintGroups of the varied parameters as `assume`s: one group's rules all
        hold (and), and at least one group does (or)."""
        out = []
        t = self.template
        for name in self.used:
            groups = list(self.decls[name].iterfind("ConstraintGroup"))
            if not groups:
                continue
            ors, texts = [], []
            for g in groups:
                ands, words = [], []
                for c in g.iterfind("ValueConstraint"):
                    rule = c.get("rule", "")
                    if rule not in RULE_OPS:
                        t.error(c, f"rule=\"{rule[:40]}\" is not one of {', '.join(RULE_OPS)}")
                        continue
                    try:
                        v = float(t.resolve(c.get("value", "")))
                    except (KeyError, SyntaxError, ValueError, ArithmeticError, RecursionError, MemoryError):
                        t.error(c, f"value=\"{c.get('value', '')[:40]}\" of a constraint on '{name}' is not a number")
                        continue
                    v *= self.scale(name)
                    ands.append(E.Binary(op=RULE_OPS[rule], left=E.Param(name=name), right=E.Num(value=v)))
                    words.append(f"{name} {RULE_OPS[rule]} {v!r}")
                if not ands:
                    t.error(g, f"a <ConstraintGroup> of '{name}' has no <ValueConstraint>")
                    continue
                ors.append(_fold("and", ands))
                texts.append(" and ".join(words))
            if ors:
                out.append(AssumptionPlan(name=f"{name}_valid", expr=_fold("or", ors),
                                          text=" or ".join(f"({x})" if len(texts) > 1 else x for x in texts)))
        self.sink.items.extend(t.sink.items)
        self.sources.update(t.sources)
        return out

    # -- the .addt

    def finish(self, pvd, plan, tmpl: Imported, assumptions) -> Imported | None:
        total, runs = grid_cell_count(plan), None
        kind = "stochastic" if plan.sweep.sampler else "deterministic"
        if assumptions and not plan.sweep.sampler:
            runs = count_runs(plan)
            self.approx(pvd, f"{total - runs} of {total} combinations break the scenario's ValueConstraintGroups: "
                             f"they are skipped ({runs} run(s); the run report counts them per constraint)")
        elif assumptions:
            self.approx(pvd, "a draw that breaks the scenario's ValueConstraintGroups is drawn again (counted per "
                             "constraint in the run report), so all numberOfTestRuns runs are valid ones")
        comment = (f"Imported from {self.path.name} (a {kind} ParameterValueDistribution) and its scenario "
                   f"{Path(self.template.path).name} by addtc import\n"
                   f"{sum(d.code.startswith('W08') for d in self.sink.items)} element(s) not translated "
                   "or approximated: see the diagnostics")
        try:
            text = print_plan(plan, comment=comment)
        except PrinterError as exc:
            self.error(pvd, f"the translated scenario cannot be printed: {exc}")
            return None
        if len(text.encode()) > self.limits.source_bytes:
            self.error(pvd, f"the .addt would be {len(text.encode()):,} bytes, more than {self.limits.source_bytes:,} "
                            "(limit `source_bytes`, docs/limits.md)", code="E0701")
            return None
        files = side_files(plan)
        with tempfile.TemporaryDirectory() as tmp:
            for name, body in files.items():
                (Path(tmp) / name).write_text(body)
            check = compile_source(text, path=f"{self.path.stem}.addt", base_dir=tmp, limits=self.limits)
        if not check.ok:
            for d in check.diagnostics:
                if d.is_error:
                    self.error(pvd, f"the translated scenario does not compile: [{d.code}] {d.message}")
            self.sources.update(check.sources)
            return None
        return Imported(text, check.plan, self.sink.items, self.sources, files, tmpl.entities)


class _Template(Translate):
    """The template, with the varied parameters kept where `${...}` arithmetic uses them.

    The importer evaluates `${$EgoSpeed / 3.6}` to a number; a parameter the distribution
    varies must stay a parameter there. An expression linear in one varied parameter
    (a * x + b, checked at three points) becomes `c * P + b`, and P's unit is the one
    whose factor is a where a matches a unit of the place's dimension (esmini's km/h:
    `${$EgoSpeed / 3.6}` makes EgoSpeed a speed in km/h, 120 -> 33.3 m/s, and the
    expression just `EgoSpeed`); otherwise SI (scale 1). A parameter's scale is fixed by
    its first use (a plain `$P` fixes 1)."""

    varied: frozenset[str] = frozenset()

    def __init__(self, *args, **options):
        super().__init__(*args, **options)
        self.scales: dict[str, float] = {}  # parameter -> SI per unit of its value in the file

    def number(self, el, attr: str, dim=units.DIMENSIONLESS, default: float | None = None,
               keep: bool = True) -> E.Expr:
        ref = el.get(attr, "")
        if keep and ref.startswith("${") and ref.endswith("}"):
            got = self.linear(ref[2:-1], dim)
            if got is not None:
                return got
        out = super().number(el, attr, dim, default, keep)
        if isinstance(out, E.Param) and out.name in self.varied:
            k = self.scales.setdefault(out.name, 1.0)
            if k != 1.0:
                return E.Binary(op="*", left=E.Num(value=1.0 / k), right=out)
        return out

    def linear(self, body: str, dim) -> E.Expr | None:
        names = set(re.findall(r"\$([A-Za-z_]\w*)", body))
        if len(names) != 1 or not names <= self.varied:
            return None
        (name,) = names
        try:
            f = [arith(ast.parse(re.sub(r"\$" + name + r"\b", repr(float(x)), body), mode="eval"))
                 for x in (0.0, 1.0, 2.0)]
        except (SyntaxError, ValueError, ArithmeticError, RecursionError, MemoryError):
            return None
        a, b = f[1] - f[0], f[0]
        if not all(map(math.isfinite, f)) or a == 0 or not math.isclose(f[2], b + 2 * a, rel_tol=1e-12, abs_tol=1e-12):
            return None
        if name not in self.scales:
            unit = next((u for u in units.UNITS.values() if u.dim == dim and b == 0
                         and math.isclose(u.factor, a, rel_tol=1e-12)), None)
            self.scales[name] = unit.factor if unit is not None else 1.0
        known = self.param_dims.get(name, dim)
        self.param_dims[name] = dim if known == dim else None
        c = a / self.scales[name]
        out: E.Expr = E.Param(name=name) if math.isclose(c, 1.0, rel_tol=1e-12) else \
            E.Binary(op="*", left=E.Num(value=c), right=E.Param(name=name))
        return out if b == 0 else E.Binary(op="+", left=out, right=E.Num(value=b))

    def plan(self, header, duration: float):
        plan = super().plan(header, duration)
        params = [p.model_copy(update={"default": p.default * self.scales.get(p.name, 1.0)}) for p in plan.params]
        return plan.model_copy(update={"params": params})


for _name, _note in (
        ("Deterministic", "`grid` and `cases` axes, multiplied as OpenSCENARIO combines them"),
        ("Stochastic", "`random N seed S` (numberOfTestRuns, randomSeed; no seed: 0, W0802)"),
        ("DeterministicSingleParameterDistribution", "a `grid` axis of the parameter"),
        ("DeterministicMultiParameterDistribution", "a `cases` axis"),
        ("DistributionRange", "`grid P in [lo, lo + step, ...]` up to the upper limit"),
        ("DistributionSet", "`grid P in [a, b, ...]`"),
        ("ValueSetDistribution", "`cases P in [...], Q in [...]`: the listed combinations")):
    DISTRIBUTIONS.declare(_name, "exact", _note)
DISTRIBUTIONS.declare("UserDefinedDistribution", "refused", NOT_DRAWN["UserDefinedDistribution"])


def _domain(p: ParamPlan, lo: float, hi: float, **fields) -> ParamPlan:
    """The parameter drawn in [lo, hi]; its default (the value no sweep uses here) moved
    into the range, as the language requires."""
    if lo == hi:
        return p.model_copy(update={"default": lo})
    return p.model_copy(update={"low": lo, "high": hi, "default": min(max(p.default, lo), hi), **fields})


def _only(el):
    kids = list(el)
    return kids[0] if len(kids) == 1 else None


def _first_of(*elements):
    return next(e for e in elements if e is not None)


def _fold(op: str, parts: list) -> E.Expr:
    out = parts[0]
    for p in parts[1:]:
        out = E.Binary(op=op, left=out, right=p)
    return out


DOCUMENT_KINDS.append((names_distribution, import_distribution))
