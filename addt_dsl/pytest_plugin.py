"""pytest plugin: `.addt` scenarios as tests, with shrunk counterexamples and a failure corpus.

    pytest scenarios/                          one test per .addt file
    pytest scenarios/ --addt-per-cell          one test per sweep cell
    pytest scenarios/ --hypothesis-profile ci  fast; `nightly` is thorough

Registered through the `pytest11` entry point `addt`; `-p no:addt` switches it off.
A file is collected when its name matches the ini option `addt_files` (default
`*.addt`) and it declares a scenario (files of shared definitions for `include` are
skipped). pytest does not recurse into dot-directories, so the corpus is never
collected on its own.

A test, in the order of Hypothesis's phases (the current settings profile decides which
run, and `max_examples` sizes the search):
  reuse     replay this file's entries in the failure corpus (`.addt-failures/`, ini
            `addt_failures`): a counterexample found once fails the test again until fixed;
            an entry shrunk from another version of the scenario (its `# scenario key:`
            header) is skipped with a note, not replayed
  explicit  run the scenario's sweep (or the cell's runs)
  generate  falsify: more runs searching parameters and faults (budget by profile)
            (guided by robustness when the `target` phase is on, else uniform)
  shrink    shrink the first failure, write it to the corpus, report it

Search runs per profile (`SEARCH_RUNS`, ini `addt_search_runs`): `default` 0 (sweep and
corpus only), `ci` 10, `nightly` 300, any other profile its `max_examples`. Hypothesis
ships the `ci` profile; `nightly` is registered here unless the project has one.
Everything is seeded (`--addt-seed`), so a test gives the same verdict and the same
counterexample every time.
"""

from __future__ import annotations

import fnmatch
import os
from pathlib import Path

import pytest

# Search runs per scenario under each Hypothesis profile (ini `addt_search_runs` overrides,
# e.g. `addt_search_runs = ci=20 nightly=1000`); a profile not listed uses its
# `max_examples`. The default profile runs the sweep and the corpus only.
SEARCH_RUNS = {"default": 0, "ci": 10, "nightly": 300}
NIGHTLY_PROFILE = {"max_examples": 1000, "deadline": None}


def _register_profiles() -> None:
    """Hypothesis ships a `ci` profile (derandomized); `nightly` is added if missing."""
    from hypothesis import settings
    from hypothesis.errors import InvalidArgument

    try:
        settings.get_profile("nightly")
    except InvalidArgument:
        settings.register_profile("nightly", **NIGHTLY_PROFILE)


_register_profiles()


def search_runs_for(profile: str, max_examples: int, overrides: list[str]) -> int:
    table = dict(SEARCH_RUNS)
    for item in overrides:
        name, _, value = item.partition("=")
        if value.strip().isdigit():
            table[name.strip()] = int(value)
    return table.get(profile, max_examples)


def pytest_addoption(parser) -> None:
    group = parser.getgroup("addt", "addt-dsl scenarios")
    group.addoption("--addt-per-cell", action="store_true", default=None,
                    help="one test per sweep cell instead of one per file")
    group.addoption("--addt-seed", type=int, default=0, help="seed of the search (default 0)")
    group.addoption("--addt-jobs", type=int, default=1, help="worker processes per scenario")
    group.addoption("--addt-batch", type=int, default=None,
                    help="runs stepped together: the corpus and the sweep hand each worker batches of N runs "
                         "(default: the executors' default), the shrink runs N candidates at a time "
                         "(default 1); the verdicts and counterexamples are the same at any N")
    group.addoption("--addt-shrink-simulations", type=int, default=None,
                    help="simulation budget for shrinking a failure (default from the profile)")
    group.addoption("--addt-failures", default=None, help="failure corpus directory (ini: addt_failures)")
    group.addoption("--addt-search-runs", type=int, default=None,
                    help="search runs per scenario (default: by Hypothesis profile, see addt_search_runs)")
    parser.addini("addt_files", type="args", default=["*.addt"], help="glob patterns of scenario files to collect")
    parser.addini("addt_failures", default=".addt-failures", help="failure corpus directory, relative to rootdir")
    parser.addini("addt_per_cell", type="bool", default=False, help="one test per sweep cell")
    parser.addini("addt_search_runs", type="args", default=[],
                  help="search runs per Hypothesis profile, e.g. `ci=10 nightly=300`")


def pytest_collect_file(file_path: Path, parent):
    if file_path.suffix != ".addt":
        return None
    patterns = parent.config.getini("addt_files")
    if not any(fnmatch.fnmatch(file_path.name, p) for p in patterns):
        return None
    return AddtFile.from_parent(parent, path=file_path)


class AddtFailure(Exception):
    """A scenario failed; `message` is the report (first line: oracle and counterexample)."""

    def __init__(self, message: str, properties: list[tuple[str, str]]):
        super().__init__(message)
        self.message = message
        self.properties = properties


class AddtCompileError(Exception):
    pass


class AddtCorpusError(Exception):
    """An entry of the failure corpus cannot be replayed (it does not compile)."""


class AddtWarning(UserWarning):
    """A `warn` oracle was violated: shown in pytest's warnings summary (and as a
    `warning.NAME` property in JUnit XML), never a failure; `-W error::addt_dsl.pytest_plugin.AddtWarning`
    makes it one."""


class AddtFile(pytest.File):
    def collect(self):
        from addt_dsl.compiler.parser import parse_source
        from addt_dsl.diagnostics import DiagnosticSink

        tree = parse_source(self.path.read_bytes(), str(self.path), DiagnosticSink())
        if tree is not None and not tree.scenarios:
            return []  # shared definitions for `include`, not a test
        per_cell = self.config.getoption("addt_per_cell")
        if per_cell is None:
            per_cell = self.config.getini("addt_per_cell")
        if per_cell and tree is not None:
            plan = self._plan_or_none()
            if plan is not None and plan.sweep.grid:
                from addt_dsl.sweep import expand

                cells = []
                for spec in expand(plan).specs:
                    if spec.cell not in cells:
                        cells.append(spec.cell)
                return [AddtItem.from_parent(self, name=_cell_name(plan, c), cell=c) for c in cells]
        name = tree.scenarios[0].name if tree is not None else self.path.stem
        return [AddtItem.from_parent(self, name=name, cell=None)]

    def _plan_or_none(self):
        from addt_dsl.compiler import compile_file

        return compile_file(self.path).plan


def _cell_name(plan, cell: dict) -> str:
    from addt_dsl.printer import dim_of_name, format_const

    dims = {p.name: dim_of_name(p.dimension) for p in plan.params}
    inner = ",".join(f"{k}={format_const(v, dims[k]).replace(' ', '')}" for k, v in cell.items())
    return f"{plan.name}[{inner}]"


class AddtItem(pytest.Item):
    def __init__(self, *, cell: dict | None, **kwargs):
        super().__init__(**kwargs)
        self.cell = cell
        self.add_marker(pytest.mark.addt)

    # ---- settings
    def _settings(self):
        from hypothesis import Phase, settings

        current = settings()
        phases = set(current.phases)
        runs = self.config.getoption("addt_search_runs")
        if runs is None:
            runs = search_runs_for(settings.get_current_profile_name(), current.max_examples,
                                   self.config.getini("addt_search_runs"))
        shrink_budget = self.config.getoption("addt_shrink_simulations")
        if shrink_budget is None:
            shrink_budget = min(300, max(60, 2 * current.max_examples))
        return {
            "reuse": Phase.reuse in phases,
            "explicit": Phase.explicit in phases,
            "search_runs": runs if Phase.generate in phases else 0,
            "sampler": "cem" if Phase.target in phases else "random",
            "shrink": Phase.shrink in phases,
            "shrink_budget": shrink_budget,
            "seed": self.config.getoption("addt_seed"),
            "jobs": self.config.getoption("addt_jobs"),
            "batch": self.config.getoption("addt_batch"),
        }

    def corpus_dir(self) -> Path:
        opt = self.config.getoption("addt_failures")
        return Path(opt) if opt else Path(self.config.rootpath) / self.config.getini("addt_failures")

    def source_name(self) -> str:
        return self.relative(self.path)

    def relative(self, path: Path) -> str:
        try:
            return str(Path(path).resolve().relative_to(Path(self.config.rootpath).resolve()))
        except ValueError:
            return str(path)

    # ---- the test
    def runtest(self) -> None:
        from addt_dsl.compiler import compile_source
        from addt_dsl.diagnostics import render_text
        from addt_dsl.search import RunCache

        # Compiled under its rootdir-relative name, so reports say `scenarios/x.addt:29`; its
        # includes and maps may lie anywhere under the rootdir (`addtc --root`), e.g. maps/.
        result = compile_source(self.path.read_bytes(), path=self.source_name(), base_dir=self.path.parent,
                                root=self.config.rootpath)
        if not result.ok:
            raise AddtCompileError(render_text(result.diagnostics, result.sources))
        plan = result.plan
        opts = self._settings()
        cache = RunCache(batch=opts["batch"])
        notes: list[str] = []
        if opts["reuse"]:
            self._replay_corpus(plan, cache, opts, notes)
        failing = None
        if opts["explicit"]:
            failing = self._run_sweep(plan, cache, opts, notes)
        if failing is None and opts["search_runs"] > 0:
            failing = self._search(plan, cache, opts, notes)
        for note in notes:
            self.add_report_section("call", "addt", note)
        if failing is not None:
            self._report(plan, failing, cache, opts, notes)

    def _replay_corpus(self, plan, cache, opts, notes) -> None:
        from addt_dsl.printer import compile_pinned, semantic_key

        current = semantic_key(plan)
        entries = []  # (shown, spec), in corpus order, up to the first that cannot be replayed
        damaged = None
        for path, key in corpus_entries(self.corpus_dir(), self.path, plan.name):
            shown = self.relative(path)
            if key and key != current:  # shrunk from an earlier version of the scenario
                entries.append((shown, key))
                continue
            try:
                entries.append((shown, compile_pinned(path.read_bytes(), path=shown, base_dir=path.parent)))
            except ValueError as exc:  # damaged, hand-edited, or older than the language: say which, no traceback
                damaged = AddtCorpusError(f"corpus entry {shown} cannot be replayed: {exc}\n"
                                          f"fix it, or delete it if it is stale")
                break
        # The entries run together (one batch), then are reported in corpus order as one by one.
        specs = [spec for _, spec in entries if not isinstance(spec, str)]
        outcomes = iter(cache.get_many(specs, opts["jobs"]) if specs else [])
        for shown, spec in entries:
            if isinstance(spec, str):
                notes.append(f"skipped {shown}: written for an earlier version of {self.source_name()} "
                             f"(scenario key {spec}, now {current}); delete it once the fix is kept")
                continue
            outcome = next(outcomes)
            notes.append(f"replayed {shown}: {'still fails' if outcome.failures else 'passes'}")
            if outcome.failures:
                f = outcome.primary()
                raise AddtFailure(
                    f"{f.oracle} fails again: known counterexample {shown} still fails ({f.describe()})\n"
                    f"replay: addtc {shown}",
                    [("oracle", f.oracle), ("mode", f.mode), ("counterexample", shown), ("regression", "1")])
        if damaged is not None:
            raise damaged from None

    def _run_sweep(self, plan, cache, opts, notes):
        from addt_dsl.sweep import expand

        specs = expand(plan).specs
        if self.cell is not None:
            specs = [s for s in specs if s.cell == self.cell]
        outcomes = cache.get_many(specs, opts["jobs"])
        failing = [(s, o) for s, o in zip(specs, outcomes) if o.failures]
        notes.append(f"sweep: {len(specs)} run(s), {len(failing)} failing")
        self._warn(plan, specs, outcomes, notes)
        return failing[0] + (len(failing),) if failing else None

    def _warn(self, plan, specs, outcomes, notes) -> None:
        """Violated `warn` oracles (robustness below 0; the search keeps no verdicts): a
        note, a property and an AddtWarning each, counted apart from failures."""
        import warnings

        for o in plan.oracles:
            if o.severity != "warn":
                continue
            runs = [s.run_id for s, out in zip(specs, outcomes) if out.robustness.get(o.name, 0.0) < 0]
            if runs:
                text = f"warning: {o.name} violated in {len(runs)} of {len(specs)} run(s), e.g. {runs[0]}"
                notes.append(text)
                self.user_properties.append((f"warning.{o.name}", str(len(runs))))
                warnings.warn(AddtWarning(f"{self.source_name()}: {text}"), stacklevel=1)

    def _search(self, plan, cache, opts, notes):
        from addt_dsl.search.falsify import Falsifier

        fal = Falsifier(plan, seed=opts["seed"], jobs=opts["jobs"], sampler=opts["sampler"], cache=cache)
        if fal.space.dims == 0:
            notes.append("search: the scenario has no parameter ranges or faults to search")
            return None
        report = fal.run(budget_runs=opts["search_runs"], shrink_simulations=0, stop_at_first=True)
        notes.append(f"search ({opts['sampler']}): {report.runs} run(s), "
                     + (f"first failure at run {report.first_failure_run}" if report.failures else "no failure"))
        if not report.failures:
            return None
        found = report.failures[0]
        return found.example, cache.get(found.example), found.count

    def _report(self, plan, failing, cache, opts, notes) -> None:
        from addt_dsl.search import Shrinker
        from addt_dsl.search.artifacts import ReplayMismatch, write_counterexample

        spec, outcome, n_failing = failing
        first = outcome.primary()
        props = [("oracle", first.oracle), ("mode", first.mode), ("run", spec.run_id)]
        if not opts["shrink"]:
            raise AddtFailure(f"{first.oracle} fails in run {spec.run_id or spec.key()}: {first.describe()} "
                              f"({n_failing} failing run(s); shrinking is off)", props)
        result = Shrinker(spec, nominal_plan=plan, oracle=first.oracle, cache=cache,
                          max_simulations=opts["shrink_budget"], batch=opts["batch"] or 1, jobs=opts["jobs"]).run()
        try:
            arts = write_counterexample(result, self.corpus_dir(), self.source_name(), animate=False)
        except ReplayMismatch as exc:  # the failure stands; only its counterexample could not be kept
            raise AddtFailure(f"{first.oracle} fails in run {spec.run_id or spec.key()}: {result.target.describe()} "
                              f"({n_failing} failing run(s)); no counterexample written: {exc}", props) from None
        path = self.relative(arts.addt)
        props.append(("counterexample", path))
        lines = [f"{first.oracle} fails: minimal counterexample {path}",
                 f"failure: {result.target.describe()} in run {spec.run_id or spec.key()} "
                 f"({n_failing} failing run(s))",
                 f"shrunk: {len(result.original.faults)} -> {len(result.best.faults)} fault(s), "
                 f"{len(result.original.plan.agents)} -> {len(result.best.plan.agents)} agent(s) in "
                 f"{result.simulations} simulations",
                 f"replay: addtc {path}", *result.changes]
        raise AddtFailure("\n".join(lines), props)

    # ---- reporting
    def repr_failure(self, excinfo, style=None):
        if isinstance(excinfo.value, AddtFailure):
            for prop in excinfo.value.properties:
                if prop not in self.user_properties:
                    self.user_properties.append(prop)
            return excinfo.value.message
        if isinstance(excinfo.value, AddtCompileError):
            return f"{self.path} does not compile:\n{excinfo.value}"
        if isinstance(excinfo.value, AddtCorpusError):
            return str(excinfo.value)
        return super().repr_failure(excinfo)

    def reportinfo(self):
        return self.path, None, f"addt: {self.name}"


def corpus_entries(corpus: Path, source: Path, scenario: str) -> list[tuple[Path, str]]:
    """Pinned counterexamples of `source`: files whose `# source:` header names a file
    with the same name and whose scenario has the same name, each with the scenario key
    its header records ("" for entries written before keys were)."""
    from addt_dsl.search.artifacts import SCENARIO_KEY_LABEL

    if not corpus.is_dir():
        return []
    out = []
    for path in sorted(corpus.glob("*.addt")):
        text = path.read_text(errors="replace")
        head = text.splitlines()[:8]
        named = next((line.split(":", 1)[1].strip() for line in head if line.startswith("# source:")), "")
        key = next((line.split(SCENARIO_KEY_LABEL, 1)[1].strip() for line in head
                    if line.startswith(f"# {SCENARIO_KEY_LABEL}")), "")
        if Path(named).name == source.name and f"scenario {scenario} {{" in text:
            out.append((path, key))
    return out


def pytest_configure(config) -> None:
    config.addinivalue_line("markers", "addt: a test collected from an .addt scenario file")


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    """On GitHub Actions, turn scenario failures into annotations on the scenario file."""
    if os.environ.get("GITHUB_ACTIONS") != "true":
        return
    for report in terminalreporter.stats.get("failed", []):
        props = dict(report.user_properties)
        if "oracle" not in props:
            continue
        path = report.location[0]
        text = str(report.longrepr).replace("%", "%25").replace("\r", "").replace("\n", "%0A")
        terminalreporter.write_line(f"::error file={path},title=addt: {props['oracle']} fails::{text}")
