"""Summaries of a results store: the counts of `summary.json` and the runs table
(pandas, CSV, Parquet). Reporting reads the store; the store knows nothing of reports."""

from __future__ import annotations

import json
from pathlib import Path

from addt_dsl.atomic import atomic_path, write_text
from addt_dsl.reporting.plots import LatencyStats
from addt_dsl.reporting.tables import latency_budget_s, runs_layout, runs_table, runs_table_chunks, summary
from addt_dsl.runtime.store import ResultStore


def store_summary(store: ResultStore) -> dict:
    """`reporting.tables.summary` over every stored run (streamed), with `not_done`: the
    runs the last sweep could not complete (lost on every attempt; not stored)."""
    out = summary(store.plan(), store.records(), store.rejected(), cells=store.records("outcome != ''"))
    not_done = store.not_done()
    if not_done:
        out["not_done"] = not_done
    return out


def store_dataframe(store: ResultStore):
    """One row per stored run: id, parameters, seed, verdict, per-oracle robustness and
    first violation time, simulated and wall seconds (pandas)."""
    return runs_table(store.plan(), store.records())


CHUNK_RUNS = 250  # rows held at once while writing a runs table (about 4 kB each as dicts and frame)


def write_csv(store: ResultStore, path: str | Path, chunk: int = CHUNK_RUNS) -> Path:
    """`store_dataframe(store).to_csv(path, index=False)`, written in chunks so that memory
    stays flat in the number of runs: one pass learns the columns, a second writes the rows."""
    layout = runs_layout(store.records())
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as f:
            wrote = False
            for df in runs_table_chunks(store.records(), layout, chunk):
                df.to_csv(f, index=False, header=not wrote)
                wrote = True
            if not wrote:  # no runs: what pandas writes for the empty table
                f.write(runs_table(store.plan(), []).to_csv(index=False))
    return Path(path)


def write_parquet(store: ResultStore, path: str | Path, chunk: int = CHUNK_RUNS) -> Path:
    """`store_dataframe(store).to_parquet(path, index=False)`, one row group per chunk."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    layout = runs_layout(store.records())
    with atomic_path(path) as tmp:
        writer = None
        try:
            for df in runs_table_chunks(store.records(), layout, chunk):
                table = pa.Table.from_pandas(df, preserve_index=False,
                                             schema=None if writer is None else writer.schema)
                if writer is None:
                    writer = pq.ParquetWriter(tmp, table.schema)
                writer.write_table(table)
        finally:
            if writer is not None:
                writer.close()
        if writer is None:
            runs_table(store.plan(), []).to_parquet(tmp, index=False)
    return Path(path)


def write_tables(out: Path, store: ResultStore, budget_s: float | None = None) -> None:
    """summary.json and runs.csv of a store; latency.json when runs recorded latencies
    (per-node percentiles and e2e latency by object count, over all runs; the share of
    time over the budget the plan's oracles declare, `budget_s` overriding it)."""
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "summary.json", json.dumps(store_summary(store), indent=2) + "\n")
    write_csv(store, out / "runs.csv")
    latency = LatencyStats()
    for r in store.records():
        if r.stats:
            latency.add(r.stats)
    if latency.hist:
        budget = budget_s if budget_s is not None else latency_budget_s(store.plan())
        write_text(out / "latency.json", json.dumps(latency.summary(budget), indent=2) + "\n")
