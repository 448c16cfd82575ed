"""Search over runs: falsification (find failures) and shrinking (minimise them).

Candidates are pinned RunSpecs (`candidates`), judged into `Outcome`s (`outcome`),
cached by `RunSpec.key()` (`cache`). `shrink` minimises one failure; `falsify` looks for
failures guided by robustness; `artifacts` writes a shrunk failure as a replayable
`.addt` file plus its trace.
"""

from addt_dsl.search.cache import RunCache
from addt_dsl.search.outcome import Failure, Outcome, evaluate
from addt_dsl.search.shrink import NotFailing, ShrinkResult, Shrinker, shrink

__all__ = ["Failure", "NotFailing", "Outcome", "RunCache", "ShrinkResult", "Shrinker", "evaluate", "shrink"]
