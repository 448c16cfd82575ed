"""The default stack behind the socket bridge, in another process, gives the same run as in process."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

pytestmark = [pytest.mark.slow, pytest.mark.torch]

ROOT = Path(__file__).resolve().parents[3]
STACK_LINE = "stack bev cruise_speed 25 m/s"


@pytest.fixture(scope="module")
def server_address():
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "addt_dsl.stack.bridge_server", "--address", "127.0.0.1:0"],
                            stdout=subprocess.PIPE, text=True, env=env, cwd=ROOT)
    try:
        line = proc.stdout.readline().strip()
        assert line.startswith("listening "), line
        yield line.split()[1]
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def _spec(source: str, stack_line: str):
    text = source.replace(STACK_LINE, stack_line).replace("duration 30 s", "duration 10 s")
    result = compile_source(text)
    assert result.ok, result.diagnostics
    # 5 % frame drops: dropped frames and stale-input events must cross the bridge identically.
    return next(s for s in expand(result.plan).specs if s.params["drop_rate"] == 0.05)


@pytest.mark.parametrize("perception", ["ground_truth", "learned"])
def test_bridge_run_matches_the_in_process_stack(overtake_source, learned_overtake_source, server_address,
                                                perception):
    settings = f"perception {perception} cruise_speed 25 m/s"
    if perception == "learned":
        overtake_source = learned_overtake_source
    local = execute(_spec(overtake_source, f"stack bev {settings}"))
    remote = execute(_spec(overtake_source, f'stack external address "{server_address}" {settings}'))
    assert remote.status == "ok", remote.error
    assert remote.trace.object_count.max() >= 1
    assert remote.digest == local.digest


# Flips that persist in the stack's memory (the planner's committed manoeuvre, the
# tracker's tracks, the controller's integrator) and, with the learned detector, in its
# weights and one inference's activations: applied by the remote, the same run.
STATE_FLIPS = """
    at 1.5 s bitflip planner.trajectory bit 53 seed 0
    during [1 s, 3 s] bitflip tracker.tracks count 2 seed 1
    at 2 s bitflip control.integral field exponent seed 2"""
TENSOR_FLIPS = """
    at 1 s bitflip perception.backbone.conv1 tensor weights field exponent count 3 seed 3
    during [1 s, 4 s] bitflip perception.head.center tensor activations count 4 seed 4"""


@pytest.mark.parametrize("perception, flips", [("ground_truth", STATE_FLIPS),
                                               ("learned", STATE_FLIPS + TENSOR_FLIPS)])
def test_stack_internal_flips_through_the_bridge_match_the_in_process_run(
        overtake_source, learned_overtake_source, server_address, perception, flips):
    source = learned_overtake_source if perception == "learned" else overtake_source
    drop = "drop lidar rate drop_rate"
    assert drop in source
    source = source.replace(drop, drop + flips)
    settings = f"perception {perception} cruise_speed 25 m/s"
    local = execute(_spec(source, f"stack bev {settings}"))
    remote = execute(_spec(source, f'stack external address "{server_address}" {settings}'))
    assert remote.status == "ok", remote.error
    flipped = {e.detail["target"] for e in remote.trace.events if e.kind == "fault" and e.detail["kind"] == "bitflip"}
    assert len(flipped) == flips.count("bitflip")  # every flip target injected, remotely
    assert remote.digest == local.digest


def test_unreachable_remote_is_a_detected_stack_failure_and_releases_the_world(overtake_source, monkeypatch):
    import pybullet

    from addt_dsl.runtime import state as state_module  # where the run's state opens its world
    from addt_dsl.runtime import world as world_module

    opened = []

    class Recorded(state_module.PhysicsWorld):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            opened.append((self, self.client))  # (asked: made now)

    monkeypatch.setattr(state_module, "PhysicsWorld", Recorded)
    spec = _spec(overtake_source, 'stack external address "127.0.0.1:9" timeout 1 s')
    result = execute(spec)  # the stack connects at its first step: failing there is an outcome, not a crash
    assert result.status == "detected" and "cannot reach" in result.error
    # The run ended after the pybullet client was opened: it is released, not leaked
    # (disconnected, or reset and idle in the process's pool for the next run).
    (world, client), = opened
    assert not world.connected
    assert not pybullet.getConnectionInfo(physicsClientId=client)["isConnected"] or \
        (client in world_module.CLIENTS.idle and pybullet.getNumBodies(physicsClientId=client) == 0)


def test_imu_and_gnss_frames_cross_the_bridge(overtake_source, server_address):
    line = "sensor lidar rate 10 Hz rays 360 range 80 m"
    assert line in overtake_source
    text = overtake_source.replace(line, line + "\n    sensor imu rate 50 Hz\n    sensor gnss rate 10 Hz")
    local = execute(_spec(text, "stack bev cruise_speed 25 m/s"))
    remote = execute(_spec(text, f'stack external address "{server_address}" cruise_speed 25 m/s'))
    assert remote.status == "ok", remote.error
    assert remote.digest == local.digest
