"""The results store: one SQLite file per sweep, one committed transaction per finished run.

Why SQLite: embedded (no server), one file a CI job can keep as an artifact, and with
write-ahead logging a commit is on disk before the next run is recorded. A coordinator
killed at any instant (SIGKILL included) leaves every committed run intact and no
half-written one; restarting the same sweep skips the runs already stored, so nothing
is lost and nothing is duplicated. `synchronous=NORMAL` keeps commits cheap: a power
loss may roll back the last few commits, which a restart simply runs again (a RunSpec
determines its result, so re-running is exact).

Rows are keyed by `(RunSpec.key(), run_id)`. A sweep's store is bound to one plan
(`ResultStore(path, plan)`, its JSON in `meta`); the search's run cache
(`ResultStore.cache`) holds runs of the many plans its candidates have, each row naming
its plan by hash (`plans` table), and is looked up by key alone. Either way a report or a
re-execution needs nothing else. Runs keep summaries
only (verdicts, robustness, latency histograms); traces are re-created on demand by
executing the stored RunSpec again. Golden-run fingerprints of `--classify` (a few
signals sampled per step) are kept as blobs beside the runs.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import math
import os
import sqlite3
import sys
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

from addt_dsl.errors import ToolError
from addt_dsl.fingerprint import code_fingerprint, code_identity, describe
from addt_dsl.plan import SCHEMA_VERSION as PLAN_SCHEMA_VERSION
from addt_dsl.plan import RunSpec, ScenarioPlan
from addt_dsl.runtime.result import RunResult, Verdict

SCHEMA_VERSION = "1"

# Latency histograms: fixed bins so that per-run summaries add up across runs.
LATENCY_BIN_S = 0.002
LATENCY_BINS = 250  # 0 .. 500 ms; the last bin also holds everything above


SQLITE_HEADER = b"SQLite format 3\x00"


class StoreMismatch(ValueError):
    """The store holds results of a different plan."""


class StoreError(ToolError):
    """The store cannot be used: damaged, not a results store, read-only, in use by another
    sweep, or the disk is full. The message is one line that names the file, what is wrong
    and what to do (the commands print it and exit 3)."""


class StoreBusy(StoreError):
    """Another process is writing the store."""


class StoreFull(StoreError):
    """The disk (or the store's filesystem) is full: what was committed stays."""


def _is_full(exc: BaseException) -> bool:
    text = str(exc).lower()
    return "disk is full" in text or "disk i/o error" in text or getattr(exc, "errno", None) == errno.ENOSPC


# One writer per store: an exclusive flock on `<store>.lock`, held for the store's life (the
# kernel drops it when the process dies, SIGKILL included, so a killed sweep never leaves a
# stale lock). Not SQLite's own locks: those last one transaction, and two sweeps
# interleaving transactions is what mixed rows. A separate file because closing any
# descriptor of the database file would drop SQLite's POSIX locks. Held per process and
# counted, so the coordinator's store and its golden-run cache (one file) share it.
_LOCKS: dict[str, list] = {}  # realpath -> [fd, count]


def _lock(path: Path) -> str:
    key = os.path.realpath(path)
    held = _LOCKS.get(key)
    if held is not None:
        held[1] += 1
        return key
    lock_path = f"{path}.lock"
    try:
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise StoreError(f"{path}: cannot write beside the store ({exc.strerror}: {lock_path}); "
                         "a sweep needs a writable directory: pick another --out or --store "
                         "(`addtc report` reads a read-only store)") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.pread(fd, 400, 0).decode(errors="replace").strip() or "another process"
        os.close(fd)
        raise StoreBusy(f"{path} is in use by another sweep ({holder}); wait for it to finish, "
                        "or give this one another --out or --store") from None
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"pid {os.getpid()}: {' '.join(sys.argv)[:300]}\n".encode(), 0)
    _LOCKS[key] = [fd, 1]
    return key


def _unlock(key: str) -> None:
    held = _LOCKS.get(key)
    if held is None:
        return
    held[1] -= 1
    if held[1] <= 0:
        del _LOCKS[key]
        os.close(held[0])  # releases the flock; the lock file stays (harmless, reused)


def _check_file(path: Path) -> None:
    """Refuse a file that is not a results store before SQLite touches it: a 0-byte file
    (SQLite would silently make it a new store) or another file (overwriting it)."""
    try:
        with open(path, "rb") as fh:
            header = fh.read(len(SQLITE_HEADER))
    except OSError as exc:
        raise StoreError(f"{path}: cannot read the results store ({exc.strerror})") from None
    if not header:
        raise StoreError(f"{path} is empty (0 bytes), not a results store; it is left as it is: "
                         "remove it, or pick another --out or --store")
    if header != SQLITE_HEADER:
        raise StoreError(f"{path} is not a results store (not an SQLite file); it is left as it is: "
                         "pick another --out or --store")


def plan_hash(plan: ScenarioPlan) -> str:
    """The plan's identity (its content, not how its path was spelled: `ScenarioPlan.identity`)
    with the fingerprint of the code that runs it."""
    content = json.dumps(plan.identity(), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256((content + code_fingerprint()).encode()).hexdigest()[:20]


def trace_stats(trace) -> dict:
    """Fixed-size summary of a trace for reports: latency histograms per node (bin index
    → ticks, bins of LATENCY_BIN_S) and e2e latency by object count (count → [ticks, sum,
    max]); keys are strings so the summary is the same before and after JSON. Samples are
    clock ticks (sample-and-hold), so histograms weigh latencies by how long they were in
    force; ticks before a node's first output (latency 0) are left out."""
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
            "fault_events", "error", "stats", "worker", "finished_at", "outcome", "injections", "plan_hash")


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

    def __init__(self, path: str | Path | None, plan: ScenarioPlan | None = None, *, fresh: bool = False,
                 create: bool = False, readonly: bool = False, verify: bool = True):
        # path None: in memory (a search cache that is not kept). `readonly`: a reader that
        # never writes and takes no lock (reports, exports, `trace`, a worker reading golden
        # fingerprints while the coordinator writes). A writer holds the store's lock (one
        # writer per store) until `close`. `verify`: check every page first (a damaged store
        # is refused in one line, not met as an SQLite error halfway through a report).
        self.path = Path(path) if path is not None else None
        self._lock_key: str | None = None
        self._db = None
        if self.path is not None:
            if not self.path.exists() and (readonly or (plan is None and not create)):
                raise FileNotFoundError(f"no results store at {self.path}")
            if not readonly:
                try:
                    self.path.parent.mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise StoreError(f"{self.path}: cannot create its directory ({exc.strerror})") from None
                self._lock_key = _lock(self.path)
        self.session = 0
        self._plan: ScenarioPlan | None = None
        self._plan_hashes: dict[int, tuple[ScenarioPlan, str]] = {}  # id(plan) -> (plan, hash), stored
        try:
            if self.path is not None and self.path.exists():
                _check_file(self.path)
            elif self.path is not None and not readonly:
                self._create_file()
            self._open(readonly, verify)
            if plan is not None:
                with self.errors("opening"):
                    self._bind(plan, fresh)
        except BaseException:
            self.close()  # a refused store keeps no lock
            raise

    def _create_file(self) -> None:
        """Make a new, empty store beside the path and rename it into place, so that no
        crash ever leaves a 0-byte or half-made file under the store's name (one that a
        later run would have to refuse)."""
        tmp = self.path.with_name(f".{self.path.name}.new-{os.getpid()}")
        with self.errors("creating the store"):
            try:
                db = sqlite3.connect(tmp, isolation_level=None)
                try:
                    self._db = db
                    db.execute("PRAGMA journal_mode=WAL")
                    self._create()
                finally:
                    self._db = None
                    db.close()
                os.replace(tmp, self.path)
            finally:
                for leftover in (tmp, Path(f"{tmp}-wal"), Path(f"{tmp}-shm")):
                    if leftover.exists():
                        leftover.unlink()

    def _open(self, readonly: bool, verify: bool) -> None:
        with self.errors("opening"):
            if readonly:
                uri = self.path.resolve().as_uri()
                self._db = sqlite3.connect(f"{uri}?mode=ro", uri=True, isolation_level=None, timeout=30.0)
                try:
                    self._db.execute("SELECT COUNT(*) FROM sqlite_master").fetchone()
                except sqlite3.OperationalError:
                    # A write-ahead-log store in a read-only directory (or on read-only media):
                    # SQLite cannot make its shared-memory file there. Nobody can be writing
                    # it either, so it is read as an immutable file.
                    self._db.close()
                    self._db = sqlite3.connect(f"{uri}?mode=ro&immutable=1", uri=True, isolation_level=None)
            else:
                existing = self.path is not None and self.path.exists() and self.path.stat().st_size > 0
                self._db = sqlite3.connect(self.path or ":memory:", isolation_level=None, timeout=30.0)
                if existing:  # checked before anything is written to it
                    self._check_tables()
                    if verify:
                        self._verify()
                self._db.execute("PRAGMA journal_mode=WAL")
                self._db.execute("PRAGMA synchronous=NORMAL")
                self._create()
                return
            if self.path is not None:
                self._check_tables()
                if verify:
                    self._verify()

    def _verify(self) -> None:
        problems = [row[0] for row in self._db.execute("PRAGMA quick_check(3)")]
        if problems != ["ok"]:
            raise sqlite3.DatabaseError(f"database disk image is malformed ({problems[0]})")

    def _check_tables(self) -> None:
        tables = {row[0] for row in self._db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if "meta" not in tables or "runs" not in tables:
            raise StoreError(f"{self.path} is an SQLite database but not a results store (tables: "
                             f"{', '.join(sorted(tables)) or 'none'}); it is left as it is: pick another "
                             "--out or --store")
        schema = self.meta("schema")
        if schema is not None and schema != SCHEMA_VERSION:  # its rows mean something else: never mixed
            raise StoreError(f"{self.path} is a results store of schema {schema!r}, made by another version of "
                             f"addtc (this one reads schema {SCHEMA_VERSION}); it is left as it is: read it with "
                             "the addtc that made it, or pick another --out or --store")

    def errors(self, doing: str) -> _Errors:
        """Turn SQLite errors into one-line `StoreError`s naming the file and the remedy."""
        return _Errors(self, doing)

    def error_of(self, exc: BaseException, doing: str) -> StoreError:
        where = self.path if self.path is not None else "the in-memory store"
        first = (str(exc).splitlines() or [type(exc).__name__])[0]
        if _is_full(exc):
            return StoreFull(f"{where}: the disk is full ({first}) while {doing}; every run committed so far "
                             "is kept: free some space and run the same command again to resume")
        if isinstance(exc, sqlite3.OperationalError) and "readonly" in first.replace("-", "").replace(" ", ""):
            return StoreError(f"{where} is read-only ({first}); a sweep must write its store: pick another "
                              "--out or --store (`addtc report` reads a read-only store)")
        if isinstance(exc, sqlite3.OperationalError) and "locked" in first:
            return StoreBusy(f"{where} is locked by another process ({first}); wait for it to finish")
        if isinstance(exc, sqlite3.DatabaseError) and not isinstance(exc, sqlite3.OperationalError) \
                or "malformed" in first or "not a database" in first:
            return self.damaged(first)
        return StoreError(f"{where}: {first} while {doing}")

    def damaged(self, what: str) -> StoreError:
        """A store SQLite can read but whose contents are not what addtc writes (a malformed
        page, or a row or plan edited or damaged by something else): one line, salvage remedy."""
        where = self.path if self.path is not None else "the in-memory store"
        return StoreError(f"{where} is damaged ({what}); copy its readable runs into a new store with "
                          f"`addtc report {where} --salvage NEW.sqlite`, then resume with --store NEW.sqlite")

    @classmethod
    def cache(cls, path: str | Path | None = None) -> ResultStore:
        """The search's run cache: runs of any plans, found by `RunSpec.key()`. Keys carry
        the code fingerprint, so runs made by other code are never found: they run again."""
        store = cls(path, create=True)
        scenario = store.meta("scenario")
        if store.meta("plan") is not None:  # one plan's runs: another plan's would be mixed into its reports
            store.close()
            raise StoreMismatch(f"{path} is the results store of a sweep of {scenario!r}, not a run cache: runs "
                                "of other plans would be mixed into it; pick another --cache")
        store.set_meta("code", json.dumps(code_identity()))
        return store

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
                outcome TEXT NOT NULL DEFAULT '', injections TEXT NOT NULL DEFAULT '{}',
                plan_hash TEXT NOT NULL DEFAULT '', PRIMARY KEY (key, run_id))""")
            # Stores written before outcomes (injections, plan hashes) were recorded lack the column;
            # a run without a plan hash is of the store's bound plan.
            columns = {row[1] for row in self._db.execute("PRAGMA table_info(runs)")}
            for name, default in (("outcome", "''"), ("injections", "'{}'"), ("plan_hash", "''")):
                if name not in columns:
                    self._db.execute(f"ALTER TABLE runs ADD COLUMN {name} TEXT NOT NULL DEFAULT {default}")
            self._db.execute("CREATE TABLE IF NOT EXISTS plans (hash TEXT PRIMARY KEY, plan TEXT NOT NULL)")
            self._db.execute("CREATE TABLE IF NOT EXISTS blobs (key TEXT PRIMARY KEY, data BLOB NOT NULL)")
            self._db.execute("""CREATE TABLE IF NOT EXISTS sessions (
                id INTEGER PRIMARY KEY, started_at REAL, command TEXT, executor TEXT, workers INTEGER)""")
            self._db.execute("INSERT OR IGNORE INTO meta VALUES ('schema', ?)", (SCHEMA_VERSION,))

    def _tx(self):
        db = self._db

        class _Tx:
            def __enter__(self_inner):
                db.execute("BEGIN IMMEDIATE")

            def __exit__(self_inner, exc_type, *_):
                if exc_type is None:
                    try:
                        db.execute("COMMIT")
                        return
                    except sqlite3.Error:  # e.g. the disk filled up: nothing of it stays
                        if db.in_transaction:
                            db.execute("ROLLBACK")
                        raise
                if db.in_transaction:
                    db.execute("ROLLBACK")

        return _Tx()

    def _bind(self, plan: ScenarioPlan, fresh: bool) -> None:
        digest = plan_hash(plan)
        stored = self.meta("plan_hash")
        code = json.dumps(code_identity())
        if stored is None and not fresh and len(self):
            raise StoreMismatch(
                f"{self.path} holds {len(self)} run(s) but no plan: it is a run cache of `addtc falsify` or "
                "`addtc shrink` (--cache), not a sweep's results store, and its runs would be mixed into this "
                "sweep's; pick another --out or --store, or use --fresh to discard them")
        if stored is not None and stored != digest:
            stored_code = self.meta("code")
            if not fresh and stored_code != code:
                raise StoreMismatch(
                    f"{self.path} holds results made by other code ({describe(json.loads(stored_code or 'null'))}; "
                    f"this is {describe(code_identity())}): they would not match new runs; use --fresh to run "
                    "them again or --store to pick another file")
            if not fresh:
                raise StoreMismatch(
                    f"{self.path} holds results of another plan ({self.meta('scenario')!r}, plan {stored}): the "
                    f"scenario changed; to keep those results run into a new store beside it, --store "
                    f"{self.path.with_name(f'{self.path.stem}-{digest[:8]}{self.path.suffix}')}, or use --fresh "
                    "to discard them")
        with self._tx():
            if fresh or (stored is not None and stored != digest):
                # Blobs stay: they are keyed by content (golden fingerprints by RunSpec key).
                for table in ("runs", "sessions", "plans"):
                    self._db.execute(f"DELETE FROM {table}")
                self._db.execute("DELETE FROM meta WHERE name != 'schema'")
            self._db.executemany("INSERT OR REPLACE INTO meta VALUES (?, ?)", [
                ("plan_hash", digest), ("plan", plan.model_dump_json()), ("scenario", plan.name), ("code", code)])
        self._plan = plan
        self._plan_hashes[id(plan)] = (plan, digest)

    def begin_session(self, command: str = "", executor: str = "", workers: int = 0) -> int:
        with self.errors("starting a session"), self._tx():
            cur = self._db.execute("INSERT INTO sessions (started_at, command, executor, workers) VALUES (?,?,?,?)",
                                   (time.time(), command, executor, workers))
        self.session = int(cur.lastrowid)
        return self.session

    def close(self) -> None:
        if self._db is not None:
            self._db.close()
            self._db = None
        if self._lock_key is not None:
            _unlock(self._lock_key)
            self._lock_key = None

    def __enter__(self):
        return self

    def __exit__(self, *_):
        self.close()

    # ---- meta
    def meta(self, name: str) -> str | None:
        row = self._db.execute("SELECT value FROM meta WHERE name = ?", (name,)).fetchone()
        return row[0] if row else None

    def set_meta(self, name: str, value) -> None:
        with self.errors("writing"), self._tx():
            self._db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)",
                             (name, value if isinstance(value, str) else json.dumps(value)))

    def plan(self) -> ScenarioPlan:
        if self._plan is None:
            text = self.meta("plan")
            if text is None:
                raise StoreError(f"{self.path} holds no plan: it is a run cache of `addtc falsify` or `addtc "
                                 "shrink`, not a sweep's results store (`addtc trace FILE RUN_ID` re-runs one "
                                 "of its runs)")
            self._plan = self._stored_plan(text)
        return self._plan

    def _stored_plan(self, text: str, what: str = "") -> ScenarioPlan:
        """A stored plan (`what`: the run whose plan it is; "" for the store's own plan). A
        store damaged there, or made by another version of the plan's schema, is a one-line
        StoreError."""
        try:
            return ScenarioPlan.model_validate_json(text)
        except ValueError as exc:  # pydantic's ValidationError is a ValueError
            try:
                version = json.loads(text).get("schema_version")
            except (ValueError, AttributeError):
                version = None
            if isinstance(version, str) and version != PLAN_SCHEMA_VERSION:
                raise StoreError(f"{self.path} holds a plan of schema {version!r}, made by another version of "
                                 f"addtc (this one reads plan schema {PLAN_SCHEMA_VERSION}): read it with the "
                                 "addtc that made it") from None
            first = (str(exc).splitlines() or [type(exc).__name__])[0]
            if what:
                raise self.damaged(f"the plan of {what} cannot be read: {first}") from None
            # The runs are intact: a sweep's writer stores its plan again.
            raise StoreError(f"{self.path} is damaged (its plan cannot be read: {first}); run the sweep again "
                             f"on it (`addtc FILE --store {self.path}`): it writes the plan again and keeps "
                             "the runs") from None

    def _meta_json(self, name: str, default: str, kind: type):
        try:
            value = json.loads(self.meta(name) or default)
        except ValueError:
            value = None
        if not isinstance(value, kind):
            raise self.damaged(f"its {name!r} entry is not a JSON {kind.__name__}")
        return value

    def rejected(self) -> Counter:
        return Counter(self._meta_json("rejected", "{}", dict))

    def not_done(self) -> list:
        """Run ids a sweep could not complete (`lost`), as its last session left them."""
        return self._meta_json("not_done", "[]", list)

    # ---- writing
    def _plan_hash(self, plan: ScenarioPlan) -> str:
        known = self._plan_hashes.get(id(plan))
        if known is not None and known[0] is plan:
            return known[1]
        digest = plan_hash(plan)
        with self._tx():
            self._db.execute("INSERT OR IGNORE INTO plans VALUES (?, ?)", (digest, plan.model_dump_json()))
        self._plan_hashes[id(plan)] = (plan, digest)
        return digest

    def add(self, r: RunResult, plan: ScenarioPlan | None = None) -> bool:
        """Commit one finished run of `plan` (default: the store's); False if it was already
        stored (nothing changes), except that a classified run gives a stored unclassified
        one its outcome (a run repeats bit for bit: the rest of the row is the same)."""
        with self.errors(f"storing run {r.run_id}"):
            digest = self._plan_hash(plan) if plan is not None else ""
        verdicts = [{"name": v.name, "severity": v.severity, "robustness": _json_float(v.robustness),
                     "passed": v.passed, "first_violation_s": v.first_violation_s, "mode": v.mode}
                    for v in r.verdicts]
        injections = {"events": {str(k): n for k, n in r.injections.items()},
                      "drawn": {str(k): list(b) for k, b in r.drawn_values.items()}}
        with self.errors(f"storing run {r.run_id}"), self._tx():
            cur = self._db.execute(
                f"INSERT OR IGNORE INTO runs ({', '.join(_COLUMNS)}) VALUES ({', '.join('?' * len(_COLUMNS))})",
                (r.key, r.run_id, r.seq, self.session, r.status, int(r.passed), r.seed, r.repeat_index,
                 json.dumps(r.params), json.dumps(r.cell), r.spec_json, json.dumps(verdicts),
                 ";".join(r.failed_oracles), r.sim_time_s, r.wall_time_s, r.digest, r.fault_events, r.error,
                 json.dumps(r.stats), r.worker, time.time(), r.outcome, json.dumps(injections), digest))
            if cur.rowcount == 0 and r.outcome:
                cur = self._db.execute("UPDATE runs SET outcome = ? WHERE key = ? AND run_id = ? AND outcome = ''",
                                       (r.outcome, r.key, r.run_id))
        return cur.rowcount == 1

    # ---- reading
    def done(self, classified: bool = False) -> set[tuple[str, str]]:
        """(key, run_id) of every stored run: what a resumed sweep skips; `classified`: only
        the runs that carry an outcome class (a `--classify` sweep runs the others again)."""
        where = " WHERE outcome != ''" if classified else ""
        return set(self._db.execute(f"SELECT key, run_id FROM runs{where}"))

    def __len__(self) -> int:
        return self._db.execute("SELECT COUNT(*) FROM runs").fetchone()[0]

    def records(self, where: str = "", args: tuple = (), order: str = "seq, run_id",
                limit: int | None = None) -> Iterator[RunResult]:
        """Stored runs, streamed (`where` is an SQL condition over the `runs` columns)."""
        sql = f"SELECT {', '.join(_COLUMNS)} FROM runs" + (f" WHERE {where}" if where else "")
        sql += f" ORDER BY {order}" + (f" LIMIT {int(limit)}" if limit else "")
        with self.errors("reading runs"):
            for row in self._db.execute(sql, args):
                yield self._read(dict(zip(_COLUMNS, row)))

    def _read(self, row: dict) -> RunResult:
        try:
            return _record(row)
        except _ROW_ERRORS as exc:
            first = f"no {exc}" if isinstance(exc, KeyError) else (str(exc).splitlines() or [type(exc).__name__])[0]
            raise self.damaged(f"run {row['run_id']!r} cannot be read: {first}") from None

    def failing(self, limit: int | None = None) -> Iterator[RunResult]:
        return self.records("passed = 0", limit=limit)

    def find(self, key: str) -> RunResult | None:
        """A stored run with this RunSpec key (the search's cache lookup)."""
        return next(self.records("key = ?", (key,), order="run_id", limit=1), None)

    def spec(self, record: RunResult) -> RunSpec:
        """The exact RunSpec of a stored run (same key, so same trace)."""
        row = self._db.execute("SELECT plans.plan FROM runs JOIN plans ON plans.hash = runs.plan_hash "
                               "WHERE runs.key = ? AND runs.run_id = ?", (record.key, record.run_id)).fetchone()
        plan = self._stored_plan(row[0], f"run {record.run_id!r}") if row else self.plan()
        try:
            fields = json.loads(record.spec_json)
            if not isinstance(fields, dict):
                raise ValueError("not a JSON object")
            return RunSpec(plan=plan, **fields)
        except (ValueError, TypeError) as exc:  # pydantic's ValidationError is a ValueError
            first = (str(exc).splitlines() or [type(exc).__name__])[0]
            raise self.damaged(f"the RunSpec of run {record.run_id!r} cannot be read: {first}") from None

    # ---- salvage
    @staticmethod
    def salvage(damaged: str | Path, into: str | Path) -> tuple[int, int]:
        """Copy every readable run of a damaged store (row by row: a malformed page costs
        the rows on it, not the rest) with its plan into a new store at `into`; (copied,
        unreadable). Resuming the sweep on the new store runs the lost runs again."""
        damaged, into = Path(damaged), Path(into)
        if into.exists():
            raise StoreError(f"{into} exists; --salvage writes a new store: pick a new file name")
        src = sqlite3.connect(f"{damaged.resolve().as_uri()}?mode=ro", uri=True)
        try:
            try:
                meta = dict(src.execute("SELECT name, value FROM meta").fetchall())
                plans = src.execute("SELECT hash, plan FROM plans").fetchall()
                last = src.execute("SELECT MAX(rowid) FROM runs").fetchone()[0] or 0
            except sqlite3.Error as exc:
                raise StoreError(f"{damaged}: its plan cannot be read ({exc}); nothing can be salvaged: "
                                 "run the sweep again into a new store") from None
            copied = lost = 0
            with ResultStore(into, create=True, verify=False) as out:
                with out.errors("salvaging"), out._tx():
                    out._db.executemany("INSERT OR REPLACE INTO meta VALUES (?, ?)", meta.items())
                    out._db.executemany("INSERT OR IGNORE INTO plans VALUES (?, ?)", plans)
                    for rowid in range(1, last + 1):
                        try:
                            row = src.execute(f"SELECT {', '.join(_COLUMNS)} FROM runs WHERE rowid = ?",
                                              (rowid,)).fetchone()
                            if row is None:
                                continue
                            _record(dict(zip(_COLUMNS, row)))  # readable as a run, not only as bytes
                        except (sqlite3.Error, *_ROW_ERRORS):
                            lost += 1
                            continue
                        out._db.execute(f"INSERT OR IGNORE INTO runs ({', '.join(_COLUMNS)}) "
                                        f"VALUES ({', '.join('?' * len(_COLUMNS))})", row)
                        copied += 1
            return copied, lost
        finally:
            src.close()

    # ---- blobs (golden-run fingerprints)
    def blob(self, key: str) -> bytes | None:
        row = self._db.execute("SELECT data FROM blobs WHERE key = ?", (key,)).fetchone()
        return row[0] if row else None

    def put_blob(self, key: str, data: bytes) -> None:
        with self.errors("writing"), self._tx():
            self._db.execute("INSERT OR REPLACE INTO blobs VALUES (?, ?)", (key, data))


class _Errors:
    """`ResultStore.errors`: a context that re-raises SQLite and OS errors as StoreErrors."""

    __slots__ = ("store", "doing")

    def __init__(self, store: ResultStore, doing: str):
        self.store, self.doing = store, doing

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc is None or not isinstance(exc, (sqlite3.Error, OSError)) or isinstance(exc, StoreError):
            return False
        raise self.store.error_of(exc, self.doing) from exc


# What a row edited or damaged by something other than addtc raises when read (JSON that
# does not parse, or parses to the wrong shape).
_ROW_ERRORS = (ValueError, TypeError, KeyError, AttributeError)


# The type each column holds as addtc writes it (SQLite stores any value in any column).
_ROW_TYPES = {**dict.fromkeys(("seq", "session", "seed", "repeat_index", "passed"), (int,)),
              **dict.fromkeys(("key", "run_id", "status", "spec", "failed_oracles"), (str,)),
              **dict.fromkeys(("digest", "error", "worker", "outcome", "plan_hash", "stats", "injections"),
                              (str, type(None))),
              **dict.fromkeys(("sim_time_s", "wall_time_s", "finished_at"), (float, int, type(None))),
              "fault_events": (int, type(None))}


def _check_row(row: dict) -> None:
    for name, types in _ROW_TYPES.items():
        if type(row[name]) not in types:
            raise TypeError(f"{name} is {row[name]!r}")
    for name in ("params", "cell"):
        values = json.loads(row[name])
        if not isinstance(values, dict) or not all(type(v) in (float, int) for v in values.values()):
            raise TypeError(f"{name} is not a JSON object of numbers")
    verdicts = json.loads(row["verdicts"])
    if not isinstance(verdicts, list) or not all(isinstance(v, dict) for v in verdicts):
        raise TypeError("verdicts is not a JSON list of objects")
    for v in verdicts:
        if not (isinstance(v["name"], str) and isinstance(v["severity"], str) and type(v["passed"]) is bool
                and type(v["robustness"]) in (float, int, str) and isinstance(v.get("mode", ""), str)
                and type(v["first_violation_s"]) in (float, int, type(None))):
            raise TypeError(f"a verdict is {v!r}")


def _record(row: dict) -> RunResult:
    _check_row(row)
    verdicts = [Verdict(v["name"], v["severity"], _float(v["robustness"]), v["passed"],
                        v["first_violation_s"], v.get("mode", "")) for v in json.loads(row["verdicts"])]
    stats = json.loads(row["stats"] or "{}")
    injections = json.loads(row["injections"] or "{}")
    if not isinstance(stats, dict) or not isinstance(injections, dict):
        raise TypeError("stats or injections is not a JSON object")
    return RunResult(run_id=row["run_id"], key=row["key"], spec_json=row["spec"], params=json.loads(row["params"]),
                     cell=json.loads(row["cell"]), seed=row["seed"], repeat_index=row["repeat_index"],
                     status=row["status"], verdicts=verdicts, error=row["error"] or "",
                     sim_time_s=row["sim_time_s"] or 0.0, wall_time_s=row["wall_time_s"] or 0.0,
                     digest=row["digest"] or "", fault_events=row["fault_events"] or 0, stats=stats,
                     seq=row["seq"], worker=row["worker"] or "", session=row["session"],
                     outcome=row["outcome"] or "",
                     injections={int(k): n for k, n in injections.get("events", {}).items()},
                     drawn_values={int(k): tuple(b) for k, b in injections.get("drawn", {}).items()})
