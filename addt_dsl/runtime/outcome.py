"""Outcome classes of faulty runs, against the fault-free twin run ("golden run").

For a RunSpec with faults, the golden run is the same RunSpec with `faults=[]` (same
parameters, same seed, so the same perception noise and traffic). A faulty run is

- `detected`: the stack raised (exception, watchdog on NaN/inf commands) or the vehicle
  state became non-finite: `RunResult.status == "detected"`;
- `masked`:   no observable difference from the golden run: the ego trajectory (x, y,
  heading, speed) and the stack's outputs (steer, accel commands) agree sample by sample
  within `TOLERANCE` and the runs have the same length;
- `hazard`:   outputs differed and a hard oracle failed;
- `silent`:   outputs differed and no oracle failed (silent data corruption);
- `twin_failed`: the golden run itself failed a hard oracle (or the stack stopped it): the
  scenario fails without the fault, so whatever the faulty run did says nothing about the
  fault. Such runs are counted apart and left out of every fault statistic (a failing twin
  made 44 of 75 "hazards" in a random-parameter bit-flip campaign before this class existed);
- `error`:    the runner itself failed (a bug in the twin, not an outcome of the fault).
 Golden fingerprints are kept by their
RunSpec key in a results store (`GoldenCache`: the sweep's own store under `--classify`,
so a resumed or `--fresh` sweep reuses them; a temporary one otherwise), so classifying a
sweep costs one golden run per distinct (parameters the fault-free run reads, seed), not
one per faulty run: Table 1's 2,880 runs at four drop rates need 720. Golden
and faulty runs execute on the sweep executors (guards included); only the coordinator
writes the store, workers read golden fingerprints from it.

    from addt_dsl.runtime.outcome import classify, classify_many
    result, outcome = classify(spec)                  # one run
    pairs = classify_many(specs, jobs=2)              # a sweep: [(RunResult, outcome)]
    outcome_table(pairs, by=["drop_rate"])            # counts and rates per cell
"""

from __future__ import annotations

import base64
import io
import math
import tempfile
import traceback
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from addt_dsl.lru import LruCache
from addt_dsl.plan import RunSpec
from addt_dsl.stats import wilson_interval
from addt_dsl.runtime.execute import execute, execute_batch
from addt_dsl.runtime.executor import local_executor, run_batch, run_spec
from addt_dsl.runtime.result import RunResult
from addt_dsl.runtime.store import ResultStore

OUTCOMES = ("masked", "silent", "detected", "hazard", "twin_failed")
# The classes a fault can cause: rates and intervals are over runs whose twin passed.
FAULT_OUTCOMES = ("masked", "silent", "detected", "hazard")
# Differences below 1 µm, 1 µrad, 1 µm/s, 1 µm/s^2 are numerical ripples, not observable effects.
TOLERANCE = 1e-6
GOLDEN_MEMORY_SIZE = 4096  # golden fingerprints kept in memory per cache
_EGO_FIELDS = ("x", "y", "heading", "speed")


@dataclass(frozen=True)
class Fingerprint:
    """What an observer sees of a run: ego trajectory and stack outputs, plus its status."""

    signals: dict[str, np.ndarray]
    status: str
    passed: bool

    @classmethod
    def of(cls, result: RunResult) -> Fingerprint:
        trace = result.trace
        if trace is None:
            raise ValueError("classification needs the trace: run with keep_trace=True")
        ego = trace.actors["ego"]
        signals = {f"ego.{f}": np.asarray(getattr(ego, f), dtype=float) for f in _EGO_FIELDS}
        signals.update({k: np.asarray(v, dtype=float) for k, v in sorted(trace.outputs.items())})
        return cls(signals, result.status, result.passed)

    def differs(self, other: Fingerprint, tol: float = TOLERANCE) -> bool:
        if self.signals.keys() != other.signals.keys():
            return True
        for name, a in self.signals.items():
            b = other.signals[name]
            if a.shape != b.shape:
                return True
            # NaN on both sides is "the same"; NaN on one side is a difference.
            if not np.allclose(a, b, rtol=0.0, atol=tol, equal_nan=True):
                return True
        return False

    def to_bytes(self) -> bytes:
        buf = io.BytesIO()
        np.savez(buf, __status=np.array(self.status), __passed=np.array(self.passed), **self.signals)
        return buf.getvalue()

    @classmethod
    def from_bytes(cls, blob: bytes) -> Fingerprint:
        with np.load(io.BytesIO(blob)) as data:
            signals = {k: data[k] for k in data.files if not k.startswith("__")}
            return cls(signals, str(data["__status"]), bool(data["__passed"]))


def golden_spec(spec: RunSpec) -> RunSpec:
    """The fault-free twin of a run: same plan, parameters and seed, no faults.

    What does not change a fault-free run is cleared: the sweep bookkeeping (run id, cell,
    repeat index) and the parameters only the faults read (`drop_rate`). Two faulty runs
    that differ only in their faults share one golden run; a sweep gives such runs the
    same seed (paired cells, `sweep.py`), so a grid over drop rates needs one twin per
    scenario, not one per rate.
    """
    fault_only = spec.plan.fault_only_params()
    params = {k: v for k, v in spec.params.items() if k not in fault_only}
    return spec.model_copy(update={"faults": [], "params": params, "run_id": "golden", "cell": {},
                                   "repeat_index": 0})


class GoldenCache:
    """Fingerprints of golden runs by RunSpec key: in memory, and as blobs in the results
    store at `store_path` (a temporary store when none is given). Readers (workers) open
    the store read-only; `put` is the coordinator's."""

    def __init__(self, store_path: str | Path | None = None, *, readonly: bool = False):
        # The process-wide default cache lives as long as the process: its memory is bounded
        # (the store keeps every fingerprint; a key dropped here is read back from it).
        self.memory: LruCache[str, Fingerprint] = LruCache(GOLDEN_MEMORY_SIZE)
        self._tmp = None
        self._path = Path(store_path) if store_path is not None else None
        self.readonly = readonly
        self._store: ResultStore | None = None
        self.runs = 0  # golden runs executed (cache misses)

    @property
    def store_path(self) -> Path:
        if self._path is None:  # a temporary store, made on first use
            self._tmp = tempfile.TemporaryDirectory(prefix="addt-golden-")
            self._path = Path(self._tmp.name) / "golden.sqlite"
        return self._path

    def _db(self) -> ResultStore | None:
        if self._store is None:
            if self.readonly and not self.store_path.exists():
                return None
            self._store = ResultStore(self.store_path, readonly=self.readonly, create=True,
                                      verify=not self.readonly)
        return self._store

    def get(self, key: str) -> Fingerprint | None:
        fp = self.memory.get(key)
        if fp is not None:
            return fp
        db = self._db()
        data = db.blob(f"golden:{key}") if db is not None else None
        if data is None:
            return None
        fp = Fingerprint.from_bytes(data)
        self.memory.put(key, fp)
        return fp

    def put(self, key: str, fp: Fingerprint) -> None:
        self.memory.put(key, fp)
        if not self.readonly:
            self._db().put_blob(f"golden:{key}", fp.to_bytes())

    def golden(self, spec: RunSpec) -> Fingerprint:
        return self.goldens([spec])[0]

    def goldens(self, specs: Sequence[RunSpec]) -> list[Fingerprint]:
        """The golden fingerprint of each spec; those not cached are run as one batch, once
        per distinct golden key."""
        keyed = [(g.key(), g) for g in map(golden_spec, specs)]
        found = {key: self.get(key) for key, _ in keyed}
        missing = dict((key, g) for key, g in keyed if found[key] is None)
        for key, fp in zip(missing, golden_fingerprints(list(missing.values()))):
            self.runs += 1
            self.put(key, fp)
            found[key] = fp
        return [found[key] for key, _ in keyed]


def golden_fingerprint(golden: RunSpec) -> Fingerprint:
    """Run a golden spec; one that raises is `crashed` (its faulty runs classify as `error`)."""
    try:
        return Fingerprint.of(execute(golden, keep_trace=True))
    except Exception:  # noqa: BLE001 - recorded, never fatal to a sweep
        return Fingerprint({}, "crashed", False)


def golden_fingerprints(goldens: Sequence[RunSpec]) -> list[Fingerprint]:
    """`golden_fingerprint` of each spec, stepped as one batch (a run's trace does not depend
    on its batch); a batch whose set-up fails runs one by one, so only that run is `crashed`."""
    if len(goldens) > 1:
        try:
            return [Fingerprint.of(r) for r in execute_batch(list(goldens), keep_trace=True)]
        except Exception:  # noqa: BLE001 - isolate the run that failed: each alone
            pass
    return [golden_fingerprint(g) for g in goldens]


_DEFAULT_CACHE = GoldenCache()
def outcome_of(result: RunResult, golden: Fingerprint, tol: float = TOLERANCE) -> str:
    """The outcome class of a faulty run (with its trace) given its golden fingerprint."""
    if result.status not in ("ok", "detected") or golden.status == "crashed":
        return "error"
    if not golden.passed:
        return "twin_failed"
    if result.status == "detected":
        return "detected"
    if not Fingerprint.of(result).differs(golden, tol):
        return "masked"
    return "hazard" if not result.passed else "silent"


def _outcome(result: RunResult, golden: Fingerprint | None, tol: float) -> str:
    if golden is None:  # a run without faults is its own golden run
        if result.status not in ("ok", "detected"):
            return "error"
        return "masked" if result.passed else "twin_failed"
    return outcome_of(result, golden, tol)


def _error_result(spec: RunSpec, exc: BaseException) -> RunResult:
    return RunResult.unfinished(spec, "crashed", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}", 0.0)


def classify(spec: RunSpec, cache: GoldenCache | None = None, tol: float = TOLERANCE,
             keep_trace: bool = True) -> tuple[RunResult, str]:
    """Run `spec`, run (or fetch) its golden twin, and return (result, outcome class).

    Never raises for a failing run: a stack exception is `detected`, a runner failure is
    `error` (the result's `error` says what happened).
    """
    cache = _DEFAULT_CACHE if cache is None else cache
    try:
        golden = cache.golden(spec) if spec.faults else None
        result = execute(spec, keep_trace=True)
    except Exception as exc:  # noqa: BLE001 - recorded, never fatal to a sweep
        return _error_result(spec, exc), "error"
    outcome = _outcome(result, golden, tol)
    if not keep_trace:
        result.trace = None
    return result, outcome


# ---------------------------------------------------------------- batches

class GoldenRun:
    """What an executor's worker runs to prepare golden fingerprints: the golden run, its
    fingerprint sent back in the result (`stats["fingerprint"]`) for the coordinator to store."""

    def __call__(self, spec: RunSpec, seq: int = -1, worker: str = "") -> RunResult:
        return self._record(spec, seq, worker, golden_fingerprint(spec))

    def run_batch(self, specs: list[RunSpec], seqs: list[int], worker: str = "") -> list[RunResult]:
        """The golden runs of a batch stepped together, each fingerprinted as alone."""
        return [self._record(spec, seq, worker, fp)
                for spec, seq, fp in zip(specs, seqs, golden_fingerprints(specs))]

    @staticmethod
    def _record(spec: RunSpec, seq: int, worker: str, fp: Fingerprint) -> RunResult:
        result = RunResult.unfinished(spec, "ok", "", 0.0, seq=seq, worker=worker)
        result.stats = {"fingerprint": base64.b64encode(fp.to_bytes()).decode()}
        return result


def prepare_goldens(specs: Iterable[RunSpec], jobs: int = 1, cache: GoldenCache | None = None,
                    executor=None) -> int:
    """Run the golden twin of every faulty spec that `cache` lacks, once per distinct golden
    key, on `executor` (default: `jobs` local workers); returns how many were executed.

    A golden run that raises is cached as `crashed`: its faulty runs classify as `error`.
    """
    cache = _DEFAULT_CACHE if cache is None else cache
    missing: dict[str, RunSpec] = {}
    for s in specs:
        if s.faults:
            g = golden_spec(s)
            key = g.key()
            if key not in missing and cache.get(key) is None:
                missing[key] = g
    executor = executor or local_executor(jobs)
    if not hasattr(executor, "run_fn"):
        raise ValueError(f"the {executor.name} executor cannot run golden runs; use the local one")
    run_fn, executor.run_fn = executor.run_fn, GoldenRun()
    try:
        for result in executor.imap(enumerate(missing.values())):
            if result.status == "lost":
                continue  # not kept: a worker that classifies its twin runs it (and a resume here)
            data = result.stats.get("fingerprint")
            fp = Fingerprint.from_bytes(base64.b64decode(data)) if data else Fingerprint({}, "crashed", False)
            cache.put(result.key, fp)
            cache.runs += 1
    finally:
        executor.run_fn = run_fn
    return len(missing)


def classify_many(specs: Iterable[RunSpec], jobs: int = 1, cache: GoldenCache | None = None,
                  tol: float = TOLERANCE, executor=None) -> list[tuple[RunResult, str]]:
    """Classify many runs on `executor` (default: `jobs` local workers); results sorted by
    run id, traces dropped. Golden runs are computed once per distinct key (missing ones
    first), then every faulty run is executed and compared with its golden fingerprint."""
    cache = _DEFAULT_CACHE if cache is None else cache
    specs = list(specs)
    executor = executor or local_executor(jobs)
    prepare_goldens(specs, cache=cache, executor=executor)
    out = [(r, r.outcome) for r in ClassifyingExecutor(executor, cache.store_path, tol).imap(enumerate(specs))]
    out.sort(key=lambda pair: pair[0].run_id)
    return out


def outcome_table(pairs: Iterable[tuple[RunResult, str]], by: Sequence[str] = ()):
    """Counts of each outcome, the mission success rate over the runs whose fault-free twin
    passed (`success_rate`, 95 % Wilson `success_lo`/`success_hi`) and the mean number of
    injections per run (`fault_events`), grouped by the parameters in `by`. As fault-injection campaigns
    report them (NVBitFI): the sample size `fault_samples` (runs whose fault-free twin passed: the only runs that
    say something about the fault) and, per fault outcome class, its rate over them
    with a 95 % Wilson interval (`hazard_rate`, `hazard_lo`, `hazard_hi`, ...).

    `pairs` is streamed (e.g. from `ResultStore.records()`): running counters per group keep
    memory flat in the number of runs. The table is the one a pandas `groupby` over all rows
    gives (groups sorted, a group value that is missing or NaN drops the run)."""
    import pandas as pd

    by = list(by)
    classes = (*OUTCOMES, "error")
    groups: dict[tuple, list] = {}  # group key -> [count per class..., passed samples, runs, passed, fault_events]
    seen = False
    for r, o in pairs:
        seen = True
        key = tuple(r.params.get(p, r.cell.get(p)) for p in by) if by else (0,)
        if any(k is None or (isinstance(k, float) and math.isnan(k)) for k in key):
            continue
        acc = groups.get(key)
        if acc is None:
            acc = groups[key] = [0] * (len(classes) + 4)
        if o in classes:
            acc[classes.index(o)] += 1
        acc[-4] += bool(r.passed) and o in FAULT_OUTCOMES
        acc[-3] += 1
        acc[-2] += bool(r.passed)
        acc[-1] += r.fault_events
    if not seen:
        return pd.DataFrame()
    keys = sorted(groups)
    if len(by) > 1:
        index = pd.MultiIndex.from_tuples(keys, names=by)
    else:
        index = pd.Index([k[0] for k in keys], name=by[0] if by else None)
    rows = [groups[k] for k in keys]
    table = pd.DataFrame({name: pd.Series([a[i] for a in rows], index=index, dtype="int64")
                          for i, name in enumerate(classes)}, index=index)
    table.columns.name = "outcome"
    table["runs"] = pd.Series([a[-3] for a in rows], index=index, dtype="int64")
    n = table[list(FAULT_OUTCOMES)].sum(axis=1)
    # Mission success over the runs whose twin passed, as the class rates below.
    table["success_rate"] = pd.Series([a[-4] / m if m else math.nan for a, m in zip(rows, n)], index=index,
                                      dtype="float64")
    bounds = [wilson_interval(a[-4], m) for a, m in zip(rows, n)]
    table["success_lo"] = pd.Series([lo for lo, _ in bounds], index=index, dtype="float64")
    table["success_hi"] = pd.Series([hi for _, hi in bounds], index=index, dtype="float64")
    # Injections that happened (a flip whose site is never evaluated again is not injected).
    table["fault_events"] = pd.Series([a[-1] / a[-3] for a in rows], index=index, dtype="float64")
    table["fault_samples"] = n
    for name in FAULT_OUTCOMES:
        bounds = [wilson_interval(k, m) for k, m in zip(table[name], n)]
        table[f"{name}_rate"] = [k / m if m else math.nan for k, m in zip(table[name], n)]
        table[f"{name}_lo"] = [lo for lo, _ in bounds]
        table[f"{name}_hi"] = [hi for _, hi in bounds]
    return table


# ---------------------------------------------------------------- sweeps with a results store

class ClassifyingRun:
    """What an executor's worker runs under `addtc --classify`: the run, as `run_spec`
    records it, plus its outcome class against the golden fingerprint in `golden_dir`.

    Golden fingerprints are expected in the store at `golden_store` already (`prepare_goldens`
    with a `GoldenCache` on it); one that is missing is run here (and not stored: workers
    only read the store).
    A picklable callable, so that worker processes can be handed it.
    """

    def __init__(self, golden_store: str | Path, tol: float = TOLERANCE):
        self.golden_store = str(golden_store)
        self.tol = tol
        self._cache: GoldenCache | None = None

    def __getstate__(self):
        return {"golden_store": self.golden_store, "tol": self.tol, "_cache": None}

    def __call__(self, spec: RunSpec, seq: int = -1, worker: str = ""):
        if self._cache is None:
            self._cache = GoldenCache(self.golden_store, readonly=True)
        golden = self._cache.golden(spec) if spec.faults else None
        outcomes: list[str] = []

        def judge(result):
            outcomes.append(_outcome(result, golden, self.tol))

        record = run_spec(spec, seq, worker=worker, on_result=judge)
        record.outcome = outcomes[0] if outcomes else "error"  # no result: the run crashed
        return record

    def run_batch(self, specs: list[RunSpec], seqs: list[int], worker: str = "") -> list[RunResult]:
        """The runs of a batch stepped together (`executor.run_batch`), each classified as alone."""
        if self._cache is None:
            self._cache = GoldenCache(self.golden_store, readonly=True)
        # By key, not by position: a run that crashes is never handed to `judge`.
        faulty = [spec for spec in specs if spec.faults]
        goldens = {spec.key(): None for spec in specs}
        goldens.update(zip((spec.key() for spec in faulty), self._cache.goldens(faulty)))

        def judge(result):
            result.outcome = _outcome(result, goldens[result.key], self.tol)

        records = run_batch(specs, seqs, worker, on_result=judge)
        for record in records:
            record.outcome = record.outcome or "error"  # no result: the run crashed
        return records


class ClassifyingExecutor:
    """Wraps a local or inline executor so every run it returns carries its outcome class.

    The wrapped executor's workers run `ClassifyingRun(golden_store)`. A run the executor
    had to stop (timeout, memory, a dead worker) is an `error`: the runner, not the stack,
    failed to finish it.
    """

    def __init__(self, executor, golden_store: str | Path, tol: float = TOLERANCE):
        if not hasattr(executor, "run_fn"):
            raise ValueError(f"the {executor.name} executor cannot classify runs; use the local one")
        executor.run_fn = ClassifyingRun(golden_store, tol)
        self.inner = executor
        self.name, self.workers = executor.name, executor.workers

    def imap(self, items):
        for record in self.inner.imap(items):
            if not record.outcome:
                record.outcome = "error"
            yield record
