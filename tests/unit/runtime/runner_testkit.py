"""Plans and fake run functions for the runner tests.

`fake_run` replaces the simulation in a worker (LocalExecutor's `run_fn`): the `mode`
parameter of the RunSpec picks how the run behaves, so the executor's guards can be
tested in a fraction of a second per run.
"""

from __future__ import annotations

import os
import signal
import time

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.result import RunResult, Verdict

OK, HANG, SEGFAULT, HOG, RAISE, SPIKE, KILLED, KILLED_ONCE = 0, 1, 2, 3, 4, 5, 8, 9
HOG_MB = 400


def scenario(modes: list[int], repeat: int = 1, duration: str = "0.2 s", extra: str = "") -> str:
    return f"""
scenario guards {{
  description "runner test <script>alert(1)</script>"
  duration {duration}
  road r {{
    line length 200 m
    lanes right 1 width 3.5 m
  }}
  param mode = 0 in [0, 10]
  ego car on r lane -1 at 10 m speed 10 m/s {{
    stack bev
  }}
  expect {{
    moving: always ego.speed > 1 m/s
  }}
  sweep {{
    grid mode in [{", ".join(str(m) for m in modes)}]
    repeat {repeat}
    {extra}
  }}
}}
"""


def plan_of(text: str):
    result = compile_source(text)
    assert result.ok, result.diagnostics
    return result.plan


def _touch(n_mb: int) -> bytearray:
    block = bytearray(n_mb * 2**20)
    for i in range(0, len(block), 4096):
        block[i] = 1
    return block


def fake_run(spec, seq: int = -1, worker: str = "") -> RunResult:
    mode = int(spec.params["mode"])
    if mode == HANG:
        time.sleep(120)
    elif mode == SEGFAULT:
        os.kill(os.getpid(), signal.SIGSEGV)
    elif mode == HOG:
        hog = _touch(HOG_MB)  # noqa: F841 - held while the coordinator looks
        time.sleep(120)
    elif mode == RAISE:
        raise RuntimeError("boom")
    elif mode == SPIKE:
        del _touch(HOG_MB)[:]
    elif mode == KILLED:  # killed from outside on every attempt (the OOM killer, a lost node)
        os.kill(os.getpid(), signal.SIGKILL)
    elif mode == KILLED_ONCE:  # killed from outside on the first attempt only
        # The marker directory comes in the plan (`markers DIR` as its description): workers
        # fork from a server that may predate the test, so its environment is not the test's.
        marker = os.path.join(spec.plan.description.split("markers ", 1)[1], f"{spec.run_id}.killed")
        if not os.path.exists(marker):
            open(marker, "w").close()
            os.kill(os.getpid(), signal.SIGKILL)
    return fake_record(spec, seq, worker)


def fake_record(spec, seq: int = -1, worker: str = "") -> RunResult:
    """A passing record for `spec` (no simulation)."""
    record = RunResult.unfinished(spec, "ok", "", 0.001, seq=seq, worker=worker)
    record.verdicts = [Verdict("moving", "hard", 1.0 + spec.repeat_index, True)]
    record.digest = f"fake-{spec.seed}"
    return record


def plan_echo_run(spec, seq: int = -1, worker: str = "") -> RunResult:
    """`fake_run`, whose record names the plan the worker ran it with (its description)."""
    record = fake_run(spec, seq, worker)
    record.digest = spec.plan.description
    return record
