"""Search over runs: falsification (find failures) and shrinking (minimise them).

Candidates are pinned RunSpecs (`candidates`), judged into `RunResult`s with failure
modes (`outcome`), cached in a results store by `RunSpec.key()` (`cache`). `shrink`
minimises one failure; `falsify` looks for failures guided by robustness (its space,
`space`; its samplers, `samplers`; the report's text, `render`); `artifacts` writes a shrunk failure as a replayable
`.addt` file plus its trace.
"""

from addt_dsl.runtime.result import Failure
from addt_dsl.search.cache import RunCache
from addt_dsl.search.outcome import evaluate
from addt_dsl.search.shrink import NotFailing, ShrinkResult, Shrinker, shrink

__all__ = ["Failure", "NotFailing", "RunCache", "ShrinkResult", "Shrinker", "evaluate", "shrink"]
