"""Text of a falsification report (`addtc falsify`'s default output); the report itself
(`falsify.FalsifyReport`) is data, and its JSON form is `FalsifyReport.to_json`."""

from __future__ import annotations

from addt_dsl.search.falsify import FalsifyReport


def falsify_text(report: FalsifyReport) -> str:
    first = f", first after {report.first_failure_run} run(s)" if report.first_failure_run else ""
    lines = [f"falsify {report.scenario} ({report.sampler}): {report.runs} runs in {report.seconds:.1f} s, "
             f"{len(report.failures)} distinct failure(s){first}; {report.shrink_simulations} shrink simulations"]
    if report.ended_early:
        lines.append(f"  ended early: {report.ended_early}")
    for i, f in enumerate(report.failures, 1):
        lines.append(f"  {i}. {f.oracle} [{f.mode}]: {f.count} failing run(s), first at run {f.first_run}, "
                     f"worst robustness {f.worst_robustness:.3g}")
        lines.append(f"     origin: {f.origin}")
    if not report.failures:
        worst = ", ".join(f"{k} {v:.3g}" for k, v in sorted(report.best_robustness.items()))
        lines.append(f"  no failure; lowest robustness per oracle: {worst}")
    return "\n".join(lines)
