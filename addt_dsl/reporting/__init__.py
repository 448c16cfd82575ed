"""Reports over a results store: tables (pandas, summary.json, runs.csv), the HTML report
(`build_report`), JUnit XML (`write_junit`), figures and top-down animations."""

from addt_dsl.reporting.html import build_report
from addt_dsl.reporting.junit import write_junit
from addt_dsl.reporting.summary import store_summary, write_tables
from addt_dsl.reporting.tables import print_verdicts, runs_table, summary

__all__ = ["build_report", "print_verdicts", "runs_table", "store_summary", "summary", "write_junit", "write_tables"]
