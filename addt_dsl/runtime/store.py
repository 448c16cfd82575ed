"""The results store: one SQLite file per sweep, one committed transaction per finished run.

Why SQLite: embedded (no server), one file a CI job can keep as an artifact, and with
write-ahead logging a commit is on disk before the next run is recorded. A coordinator
killed at any instant (SIGKILL included) leaves every committed run intact and no
half-written one; restarting the same sweep skips the runs already stored, so nothing
is lost and nothing is duplicated. `synchronous=NORMAL` keeps commits cheap: a power
loss may roll back the last few commits, which a restart simply runs again (a RunSpec
determines its result, so re-running is exact).

Rows are keyed by `(RunSpec.key(), run_id)`. A store holds the runs of one plan: its
JSON is kept in the `meta` table, so a report or a re-execution needs nothing else.
Runs keep summaries only (verdicts, robustness, latency histograms); traces are
re-created on demand by executing the stored RunSpec again.
"""

from __future__ import annotations

import hashlib
import json
import math
import sqlite3
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

from addt_dsl.plan import RunSpec, ScenarioPlan


class _SummaryRow(NamedTuple):
    """The fields of a stored run that `reporting.tables.summary` counts."""

    passed: bool
    status: str
    sim_time_s: float
    wall_time_s: float
    failed_oracles: list[str]
    outcome: str = ""
    verdicts: list = []  # VerdictRecords: `reporting.tables.warned_oracles` reads them

SCHEMA_VERSION = "1"

# Outcome of a run as the executor saw it. `ok` and `detected` come from the simulation;
# the others are recorded by the executor when a run did not finish normally.
STATUSES = ("ok", "detected", "crashed", "timeout", "memory")

# Latency histograms: fixed bins so that per-run summaries add up across runs.
LATENCY_BIN_S = 0.002
LATENCY_BINS = 250  # 0 .. 500 ms; the last bin also holds everything above


class StoreMismatch(ValueError):
    """The store holds results of a different plan."""


@dataclass
class VerdictRecord:
    """One oracle's verdict on a run: what the loop's judge returns and the store keeps."""

    name: str
    severity: str
    robustness: float
    passed: bool
    first_violation_s: float | None = None


@dataclass
class RunRecord:
    """What the store keeps of one run (and what executors return)."""

    run_id: str
    key: str
    spec_json: str  # the RunSpec without its plan; `ResultStore.spec()` rebuilds it
    params: dict[str, float]
    cell: dict[str, float]
    seed: int
    repeat_index: int
    status: str
    verdicts: list[VerdictRecord]
    error: str = ""
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    digest: str = ""
    fault_events: int = 0
    stats: dict = field(default_factory=dict)
    seq: int = -1  # position in the sweep's expansion order
    worker: str = ""
    session: int = 0
    # Outcome class against the fault-free twin (`addtc --classify`, addt_dsl.runtime.outcome):
    # masked | silent | detected | hazard | error; "" when the run was not classified.
    outcome: str = ""

    @property
    def passed(self) -> bool:
        return self.status == "ok" and all(v.passed for v in self.verdicts if v.severity == "hard")

    @property
    def failed_oracles(self) -> list[str]:
        failed = [v.name for v in self.verdicts if v.severity == "hard" and not v.passed]
        if self.status == "detected":
            failed.append("stack_health")
        elif self.status != "ok":
            failed.append(self.status)
        return failed

    @classmethod
    def from_result(cls, spec: RunSpec, result, trace=None, seq: int = -1, worker: str = "") -> RunRecord:
        return cls(
            run_id=result.run_id, key=result.key, spec_json=spec_json(spec), params=dict(result.params),
            cell=dict(result.cell), seed=result.seed, repeat_index=spec.repeat_index, status=result.status,
            verdicts=[VerdictRecord(v.name, v.severity, float(v.robustness), bool(v.passed),
                                    v.first_violation_s) for v in result.verdicts],
            error=result.error, sim_time_s=result.sim_time_s, wall_time_s=result.wall_time_s,
            digest=result.digest, fault_events=result.fault_events,
            stats=trace_stats(trace) if trace is not None else {}, seq=seq, worker=worker)

    @classmethod
    def unfinished(cls, spec: RunSpec, status: str, error: str, wall_time_s: float, seq: int = -1,
                   worker: str = "", key: str | None = None) -> RunRecord:
        """A run the executor had to stop or lost (timeout, memory, crashed worker)."""
        return cls(run_id=spec.run_id, key=key or spec.key(), spec_json=spec_json(spec),
                   params=dict(spec.params), cell=dict(spec.cell), seed=spec.seed,
                   repeat_index=spec.repeat_index, status=status, verdicts=[], error=error,
                   wall_time_s=wall_time_s, seq=seq, worker=worker)


def spec_json(spec: RunSpec) -> str:
    return spec.model_dump_json(exclude={"plan"})


def plan_hash(plan: ScenarioPlan) -> str:
    return hashlib.sha256(plan.model_dump_json().encode()).hexdigest()[:20]


def trace_stats(trace) -> dict:
    """Fixed-size summary of a trace for reports: latency histograms per node (bin index
    → ticks, bins of LATENCY_BIN_S) and e2e latency by object count (count → [ticks, sum,
    max]); keys are strings so the summary is the same before and after JSON. Samples are clock ticks (sample-and-hold), so histograms
    weigh latencies by how long they were in force; ticks before a node's first output
    (latency 0) are left out."""
    import numpy as np

    out: dict = {"latency_hist": {}, "latency_max_s": {}, "e2e_by_objects": {}}
    for node, values in trace.latency.items():
        v = np.asarray(values, dtype=float)
        v = v[np.isfinite(v) & (v > 0)]
        if not len(v):
            continue
        bins = np.minimum((v / LATENCY_BIN_S).astype(np.int64), LATENCY_BINS - 1)
        idx, counts = np.unique(bins, return_counts=True)
        out["latency_hist"][node] = {str(int(i)): int(c) for i, c in zip(idx, counts)}
        out["latency_max_s"][node] = float(v.max())
    e2e = trace.latency.get("e2e")
    if e2e is not None and trace.object_count is not None and len(trace.object_count):
        e2e = np.asarray(e2e, dtype=float)
        objects = np.asarray(trace.object_count)
        ok = np.isfinite(e2e) & (e2e > 0)
        for n in np.unique(objects[ok]):
            vals = e2e[ok & (objects == n)]
            out["e2e_by_objects"][str(int(n))] = [int(len(vals)), float(vals.sum()), float(vals.max())]
    return out


_COLUMNS = ("key", "run_id", "seq", "session", "status", "passed", "seed", "repeat_index", "params",
            "cell", "spec", "verdicts", "failed_oracles", "sim_time_s", "wall_time_s", "digest",
            "fault_events", "error", "stats", "worker", "finished_at", "outcome")


def _json_float(x):
    if x is None:
        return None
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    if math.isnan(x):
        return "nan"
    return x


def _float(x):
    return float(x) if isinstance(x, str) else x


class ResultStore:
    """Open (or create) the store at `path`. With `plan`, the store is bound to it: a
    store of another plan raises `StoreMismatch` unless `fresh` clears it first."""

    def __init__(self, path: str | Path, plan: ScenarioPlan | None = None, *, fresh: bool = False):
        self.path = Path(path)
        if not self.path.exists() and plan is None:
            raise FileNotFoundError(f"no results store at {self.path}")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._db = sqlite3.connect(self.path, isolation_level=None, timeout=30.0)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        self._create()
        self.session = 0
        self._plan: ScenarioPlan | None = None
        if plan is not None:
            self._bind(plan, fresh)

    # ---- set-up
    def _create(self) -> None:
        with self._tx():
            self._db.execute("CREATE TABLE IF NOT EXISTS meta (name TEXT PRIMARY KEY, value TEXT NOT NULL)")
            self._db.execute("""CREATE TABLE IF NOT EXISTS runs (
                key TEXT NOT NULL, run_id TEXT NOT NULL, seq INTEGER NOT NULL, session INTEGER NOT NULL,
                status TEXT NOT NULL, passed INTEGER NOT NULL, seed INTEGER NOT NULL,
                repeat_index INTEGER NOT NULL, params TEXT NOT NULL, cell TEXT NOT NULL, spec TEXT NOT NULL,
                verdicts TEXT NOT NULL, failed_oracles TEXT NOT NULL, sim_time_s REAL, wall_time_s REAL,
                digest TEXT, fault_events INTEGER, error TEXT, stats TEXT, worker TEXT, finished_at REAL,
                outcome TEXT NOT NULL DEFAULT '', PRIMARY KEY (key, run_id))""")
            # Stores written before outcomes were recorded lack the column.
            columns = {row[1] for row in self._db.execute("PRAGMA table_info(runs)")}
            if "outcome" not in columns:
                self._db.execute("ALTER TABLE runs ADD COLUMN outcome TEXT NOT NULL DEFAULT ''")
            self._db.execute("""CREATE TABLE IF NOT EXISTS sessions (
                id INTEGER PRIMARY KEY, started_at REAL, command TEXT, executor TEXT, workers INTEGER)""")
            self._db.execute("INSERT OR IGNORE INTO meta VALUES ('schema', ?)", (SCHEMA_VERSION,))

    def _tx(self):
        db = self._db

        class _Tx:
            def __enter__(self_inner):
                db.execute("BEGIN IMMEDIATE")

            def __exit__(self_inner, exc_type, *_):
                db.execute("ROLLBACK" if exc_type else "COMMIT")

        return _Tx()

    def _bind(self, plan: ScenarioPlan, fresh: bool) -> None:
        digest = plan_hash(plan)
        stored = self.meta("plan_hash")
        if stored is not None and stored != digest:
            if not fresh:
                raise StoreMismatch(
                    f"{self.path} holds results of another plan ({self.meta('scenario')!r}, plan {stored}); "
                    "use --fresh to discard them or --store to pick another file")
        with self._tx():
            if fresh or (stored is not None and stored != digest):
                self._db.execute("DELETE FROM runs")
                self._db.execute("DELETE FROM sessions")
                self._db.execute("DELETE FROM meta WHERE name != 'schema'")
            self._db.executemany("INSERT OR REPLACE INTO meta VALUES (?, ?)", [
                ("plan_hash", digest), ("plan", plan.model_dump_json()), ("scenario", plan.name)])
        self._plan = plan

    def begin_session(self, command: str = "", executor: str = "", workers: int = 0) -> int:
        with self._tx():
            cur = self._db.execute("INSERT INTO sessions (started_at, command, executor, workers) VALUES (?,?,?,?)",
                                   (time.time(), command, executor, workers))
        self.session = int(cur.lastrowid)
        return self.session

    def close(self) -> None:
        self._db.close()

    def __enter__(self):
        return self

    def __exit__(self, *_):
        self.close()

    # ---- meta
    def meta(self, name: str) -> str | None:
        row = self._db.execute("SELECT value FROM meta WHERE name = ?", (name,)).fetchone()
        return row[0] if row else None

    def set_meta(self, name: str, value) -> None:
        with self._tx():
            self._db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)",
                             (name, value if isinstance(value, str) else json.dumps(value)))

    def plan(self) -> ScenarioPlan:
        if self._plan is None:
            text = self.meta("plan")
            if text is None:
                raise ValueError(f"{self.path} holds no plan")
            self._plan = ScenarioPlan.model_validate_json(text)
        return self._plan

    def rejected(self) -> Counter:
        return Counter(json.loads(self.meta("rejected") or "{}"))

    # ---- writing
    def add(self, r: RunRecord) -> bool:
        """Commit one finished run; False if it was already stored (nothing changes)."""
        verdicts = [{"name": v.name, "severity": v.severity, "robustness": _json_float(v.robustness),
                     "passed": v.passed, "first_violation_s": v.first_violation_s} for v in r.verdicts]
        with self._tx():
            cur = self._db.execute(
                f"INSERT OR IGNORE INTO runs ({', '.join(_COLUMNS)}) VALUES ({', '.join('?' * len(_COLUMNS))})",
                (r.key, r.run_id, r.seq, self.session, r.status, int(r.passed), r.seed, r.repeat_index,
                 json.dumps(r.params), json.dumps(r.cell), r.spec_json, json.dumps(verdicts),
                 ";".join(r.failed_oracles), r.sim_time_s, r.wall_time_s, r.digest, r.fault_events, r.error,
                 json.dumps(r.stats), r.worker, time.time(), r.outcome))
        return cur.rowcount == 1

    # ---- reading
    def done(self) -> set[tuple[str, str]]:
        """(key, run_id) of every stored run: what a resumed sweep skips."""
        return set(self._db.execute("SELECT key, run_id FROM runs"))

    def __len__(self) -> int:
        return self._db.execute("SELECT COUNT(*) FROM runs").fetchone()[0]

    def records(self, where: str = "", args: tuple = (), order: str = "seq, run_id",
                limit: int | None = None) -> Iterator[RunRecord]:
        """Stored runs, streamed (`where` is an SQL condition over the `runs` columns)."""
        sql = f"SELECT {', '.join(_COLUMNS)} FROM runs" + (f" WHERE {where}" if where else "")
        sql += f" ORDER BY {order}" + (f" LIMIT {int(limit)}" if limit else "")
        for row in self._db.execute(sql, args):
            yield _record(dict(zip(_COLUMNS, row)))

    def failing(self, limit: int | None = None) -> Iterator[RunRecord]:
        return self.records("passed = 0", limit=limit)

    def spec(self, record: RunRecord) -> RunSpec:
        """The exact RunSpec of a stored run (same key, so same trace)."""
        spec = RunSpec(plan=self.plan(), **json.loads(record.spec_json))
        return spec

    def summary(self) -> dict:
        from addt_dsl.reporting.tables import summary

        rows = (_SummaryRow(bool(ok), status, s or 0.0, w or 0.0, [n for n in failed.split(";") if n], outcome,
                            _verdicts(verdicts))
                for status, ok, failed, s, w, outcome, verdicts in self._db.execute(
                    "SELECT status, passed, failed_oracles, sim_time_s, wall_time_s, outcome, verdicts FROM runs"))
        return summary(self.plan(), rows, self.rejected(), cells=self.records("outcome != ''"))

    def dataframe(self):
        """One row per run: id, parameters, seed, verdict, per-oracle robustness and first
        violation time, simulated and wall seconds (pandas)."""
        from addt_dsl.reporting.tables import runs_table

        return runs_table(self.plan(), self.records())

    def to_csv(self, path: str | Path) -> Path:
        self.dataframe().to_csv(path, index=False)
        return Path(path)

    def to_parquet(self, path: str | Path) -> Path:
        self.dataframe().to_parquet(path, index=False)
        return Path(path)


def _verdicts(text: str) -> list[VerdictRecord]:
    return [VerdictRecord(v["name"], v["severity"], _float(v["robustness"]), v["passed"], v["first_violation_s"])
            for v in json.loads(text)]


def _record(row: dict) -> RunRecord:
    verdicts = _verdicts(row["verdicts"])
    stats = json.loads(row["stats"] or "{}")
    return RunRecord(run_id=row["run_id"], key=row["key"], spec_json=row["spec"], params=json.loads(row["params"]),
                     cell=json.loads(row["cell"]), seed=row["seed"], repeat_index=row["repeat_index"],
                     status=row["status"], verdicts=verdicts, error=row["error"] or "",
                     sim_time_s=row["sim_time_s"] or 0.0, wall_time_s=row["wall_time_s"] or 0.0,
                     digest=row["digest"] or "", fault_events=row["fault_events"] or 0, stats=stats,
                     seq=row["seq"], worker=row["worker"] or "", session=row["session"],
                     outcome=row["outcome"] or "")
