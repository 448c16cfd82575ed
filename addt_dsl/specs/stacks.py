"""Stacks' specs: keyword, settings, docs, nodes and fault sites, and the checks the compiler
runs on a stack's settings (sensors they need, packages outside the core install, the
sensor a network is trained for, an external stack's address). The stacks themselves are
in `addt_dsl/stack/` (`bev.py`, `bridge.py`) and load only when a run builds one.

Site names, the shipped detectors' sensors and the latency targets live here, where both
the compiler (fault targets, warnings) and the stack (the nodes publish through the sites)
read them.
"""

from __future__ import annotations

import ipaddress
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

from addt_dsl import units
from addt_dsl.registry import STACKS, ParamSpec

NODE_NAMES = ("perception", "tracker", "planner", "control")

# ---------------------------------------------------------------- the nodes' fault sites

GROUND_TRUTH_SITES = ("perception.x", "perception.y", "perception.count")
TRACKER_SITES = ("tracker.vx",)
# Stored state (memory a flip stays in): every live track's fields and last update time.
TRACKER_STATE_SITES = ("tracker.tracks",)
PLANNER_SITES = ("planner.speed", "planner.t_target", "planner.t_start", "planner.path_length", "planner.cost")
# Stored state (memory a flip stays in until the planner's own logic overwrites it):
# the manoeuvre state (lanes, the last lane change, the forward-collision check's held
# stage) and the committed lateral manoeuvre every plan publishes.
PLANNER_STATE_SITES = ("planner.state", "planner.trajectory")
# Commands (transient), PID state (kept) and the gains (parameters in memory: a
# changed gain stays changed for the rest of the run, like a memory upset).
CONTROL_SITES = ("control.steer", "control.accel", "control.integral",
                 "control.kp", "control.ki", "control.kd", "control.lateral_wn", "control.understeer")
# The learned detectors' decoded detections (LearnedPerception.sites, CameraBevPerception.sites).
NETWORK_OUTPUT_SITES = ("perception.x", "perception.y")
LANE_POLICIES = ("keep", "keep_right")

# Tensor fault sites of the learned detector, `perception.<layer>`: the network in
# `stack/learned.py` names its layers exactly so (a unit test checks it). Listed here so the
# compiler can check fault targets without importing torch.
LAYER_SITES = (
    "backbone.conv0", "backbone.conv1", "backbone.conv2", "backbone.conv3",
    "neck.lateral", "neck.fuse", "neck.lateral_fine", "neck.fine", "head.center", "head.box",
)
TENSOR_SITES = tuple(f"perception.{name}" for name in LAYER_SITES)
# The camera network's per-camera image encoder; its BEV part is the lidar detector's
# layout (`LAYER_SITES`). Sites `perception.<layer>` as for `perception learned`.
ENCODER_SITES = ("encoder.conv0", "encoder.conv1", "encoder.conv2")
CAMERA_BEV_SITES = ENCODER_SITES + LAYER_SITES
CAMERA_BEV_TENSOR_SITES = tuple(f"perception.{name}" for name in CAMERA_BEV_SITES)


# ---------------------------------------------------------------- the shipped detectors' sensors

@dataclass(frozen=True)
class DetectorLidar:
    """The lidar the shipped detector is trained for (`train.py` scans with it; the
    weights' metadata records it and a unit test holds the two together).

    360 rays × 5 channels at -6, -3, 0, +3, +6 deg, mounted at the default 1 m. The
    horizontal beam is the default one-channel lidar's; the upper beams see a truck's
    height (+3 deg clears a 1.5 m car beyond 9.5 m but meets a 3.5 m truck out to 48 m;
    +6 deg from 4.8 to 24 m), without which a truck seen from behind is just a wide car;
    the lower beams reach the road and are dropped as ground (`GridSpec.ground_m`).
    """

    rays: int = 360
    channels: int = 5
    vfov_deg: float = 12.0
    range_m: float = 80.0

    @property
    def config(self) -> str:
        """"RAYSxCHANNELS", as `synth` and `train --lidars` name lidars."""
        return f"{self.rays}x{self.channels}"

    def clause(self, rate_hz: float = 10.0) -> str:
        """The `.addt` sensor declaration of this lidar."""
        return (f"sensor lidar rate {rate_hz:g} Hz rays {self.rays} channels {self.channels} "
                f"vfov {self.vfov_deg:g} deg range {self.range_m:g} m")


DETECTOR_LIDAR = DetectorLidar()


@dataclass(frozen=True)
class DetectorRig:
    """The camera rig the shipped camera BEV weights are trained for (`camera_train`
    renders with it; the weights' metadata records it): six cameras around a mount above
    the vehicle centre, as the paper's surround view, at a low resolution so a frame
    costs little. 64 deg per camera (a little overlap), 128 x 40 px each."""

    cameras: int = 6
    width: int = 128
    height: int = 40
    fov_deg: float = 64.0
    x_m: float = 0.0
    z_m: float = 1.5

    def settings(self) -> dict:
        """The `camera_rig` sensor's settings (SI) for this rig."""
        return {"cameras": self.cameras, "width": self.width, "height": self.height,
                "fov": math.radians(self.fov_deg), "x": self.x_m, "z": self.z_m}

    def clause(self, rate_hz: float = 10.0) -> str:
        """The `.addt` sensor declaration of this rig."""
        return (f"sensor camera_rig rate {rate_hz:g} Hz cameras {self.cameras} width {self.width} "
                f"height {self.height} fov {self.fov_deg:g} deg")


DETECTOR_RIG = DetectorRig()

# ---------------------------------------------------------------- latency targets

LATENCY_MODEL_PATH = Path(__file__).resolve().parents[1] / "stack" / "latency_model.json"
DEFAULT_LATENCY_TARGET = "xavier"


def latency_targets(path: Path = LATENCY_MODEL_PATH) -> tuple[str, ...]:
    """The targets the model file declares (the `latency_target` setting's choices)."""
    return tuple(json.loads(path.read_text())["targets"])


# ---------------------------------------------------------------- external stacks' addresses

def escape(text: str, limit: int = 2000) -> str:
    """Peer text made safe to print or store: control characters (terminal escape
    sequences among them) written as \\xNN, and at most `limit` characters."""
    out = "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text[:limit])
    return out + ("..." if len(text) > limit else "")


_HOSTNAME = re.compile(r"(?=.{1,253}$)[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?"
                       r"(?:\.[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*\.?")


def parse_address(address: str, allow_port_zero: bool = False) -> tuple[str, int]:
    """`HOST:PORT` as (host, port): an IPv4 address, a host name, or an IPv6 address in
    brackets (`[::1]:5555`, returned without them, as the socket calls take it). A port
    outside 1-65535 (0 only where `allow_port_zero`: a server picking a free one) or a host
    that is none of these is a ValueError, never wrapped or passed on to fail later."""
    host, sep, port = address.rpartition(":")
    if not sep or not port.isascii() or not port.isdigit():
        raise ValueError(f"address must be HOST:PORT, not {escape(address, 200)!r}")
    number = int(port)
    if not (0 if allow_port_zero else 1) <= number <= 65535:
        raise ValueError(f"port {number} is outside {0 if allow_port_zero else 1}-65535 "
                         f"(in {escape(address, 200)!r})")
    if host.startswith("[") or host.endswith("]"):
        try:
            if not (host.startswith("[") and host.endswith("]")):
                raise ValueError
            ipaddress.IPv6Address(host[1:-1])
        except ValueError:
            raise ValueError(f"{escape(host, 200)!r} is not an IPv6 address") from None
        return host[1:-1], number
    if ":" in host:
        raise ValueError(f"write an IPv6 address in brackets: [{escape(host, 200)}]:{number}")
    if host and not _HOSTNAME.fullmatch(host):
        raise ValueError(f"{escape(host, 200)!r} is not a host name or an IP address")
    return host or "127.0.0.1", number


# ---------------------------------------------------------------- bev


@dataclass(frozen=True)
class PerceptionMode:
    """One value of `stack bev perception NAME`: what it reads and what the compiler checks
    (the stack builds the node, `stack/bev.py`'s `BUILDERS`).

    `frame_key` is the frame data entry that marks its input (lidar frames carry
    `hit_body`, camera frames `image`); `needs_sensor` is the sensor keyword the compiler
    requires on the ego (None: not enforced, as for the lidar modes, since existing
    scenarios run the default stack with a camera only, to exercise the renderer).
    `expects` is the sensor the mode is made for, `(keyword, {setting: value in SI})`: the
    compiler warns when the ego's differs (the learned detector is trained on one lidar).
    `requires` names a package outside the core install that the node imports (see
    `addt_dsl.extras`): the compiler reports its absence instead of the run failing.
    `sites` are the node's scalar fault sites (a network's detections carry no count to
    corrupt), what a fault on the node `perception` draws from.
    """

    frame_key: str
    needs_sensor: str | None = None
    expects: tuple[str, dict] | None = None
    requires: str | None = None
    sites: tuple[str, ...] = GROUND_TRUTH_SITES
    # Wall seconds per input frame beyond what the cost model counts for every stack
    # (addt_dsl/cost.py): a network's inference. Measured 2026-12-06 with
    # benchmarks/bench_cost_model.py's method on examples/suites/*table1_overtake.addt.
    frame_cost_s: float = 0.0


PERCEPTIONS = {
    "ground_truth": PerceptionMode("hit_body"),
    "learned": PerceptionMode("hit_body", expects=("lidar", {
        "rays": DETECTOR_LIDAR.rays, "channels": DETECTOR_LIDAR.channels,
        "vfov": math.radians(DETECTOR_LIDAR.vfov_deg)}), requires="torch", sites=NETWORK_OUTPUT_SITES,
        frame_cost_s=2e-3),
    "camera": PerceptionMode("image", "camera"),
    # A fidelity mode (cost per frame: docs/stack.md), not the default.
    "camera_bev": PerceptionMode("images", "camera_rig", expects=("camera_rig", {
        k: v for k, v in DETECTOR_RIG.settings().items() if k in ("cameras", "width", "height", "fov")}),
        requires="torch", sites=NETWORK_OUTPUT_SITES, frame_cost_s=8e-3),
}
# Perception modes with a network whose layers are tensor fault sites (`perception.<layer>`).
PERCEPTION_TENSOR_SITES = {"learned": TENSOR_SITES, "camera_bev": CAMERA_BEV_TENSOR_SITES}


@STACKS.register
class BevStack:
    keyword = "bev"
    params = (
        ParamSpec("perception", None, kind="word", default="ground_truth",
                  choices=tuple(PERCEPTIONS), doc="perception model: ground_truth, learned (lidar CNN), "
                                                  "camera (colour detector on the camera image) or camera_bev "
                                                  "(surround cameras lifted to a BEV grid by a network)"),
        ParamSpec("cruise_speed", units.SPEED, default=25.0, low=0.0, high=70.0, doc="desired speed"),
        ParamSpec("time_gap", units.TIME, default=1.5, low=0.1, high=10.0, doc="desired headway"),
        ParamSpec("max_lateral_accel", units.ACCELERATION, default=4.0, low=0.5, high=10.0,
                  doc="the planner slows for curves ahead to keep the lateral acceleration under this"),
        ParamSpec("stale", units.TIME, default=0.15, low=0.0, high=10.0,
                  doc="frames older than this on arrival are discarded"),
        ParamSpec("latency", None, kind="word", default="model", choices=("model", "median", "measured"),
                  doc="node latency: model (measured trend and jitter, drawn from the run seed), median "
                      "(the trend alone, no jitter) or measured (this run's compute time, HIL-like)"),
        ParamSpec("latency_target", None, kind="word", default=DEFAULT_LATENCY_TARGET, choices=latency_targets(),
                  doc="the hardware the modelled latency stands for: host (as measured) or a target "
                      "profile of latency_model.json (xavier: assumed factors, see docs/stack.md#latency)"),
        ParamSpec("planner_rate", units.FREQUENCY, default=10.0, low=1.0, high=100.0, doc="planning rate"),
        ParamSpec("control_rate", units.FREQUENCY, default=100.0, low=10.0, high=1000.0, doc="control rate"),
        ParamSpec("perception_noise", units.LENGTH, default=0.1, low=0.0, high=10.0,
                  doc="position noise of ground-truth perception (1 sigma)"),
        ParamSpec("track_max_age", units.TIME, default=1.0, low=0.0, high=10.0,
                  doc="how long the tracker coasts an object it no longer sees (0.15 s: no coasting "
                      "beyond one lidar period, like a detector without tracking)"),
        ParamSpec("lane_policy", None, kind="word", default="keep", choices=LANE_POLICIES,
                  doc="lane preference: keep (the lane the ego starts in: lane changes only when traffic "
                      "makes them) or keep_right (the rightmost driving lane)"),
        ParamSpec("lane_change_cooldown", units.TIME, default=3.0, low=0.0, high=60.0,
                  doc="a lane change within this time of the last one costs extra"),
        ParamSpec("aeb", None, kind="word", default="on", choices=("on", "off"),
                  doc="forward-collision check braking stages (warnings are reported either way)"),
        ParamSpec("aeb_warn_ttc", units.TIME, default=2.6, low=0.0, high=10.0,
                  doc="forward-collision warning below this time to collision"),
        ParamSpec("aeb_partial_ttc", units.TIME, default=1.6, low=0.0, high=10.0,
                  doc="partial braking (40 % of mu g) below this time to collision"),
        ParamSpec("aeb_full_ttc", units.TIME, default=0.9, low=0.0, high=10.0,
                  doc="full braking (mu g) below this time to collision"),
        ParamSpec("yield_gap", units.TIME, default=1.5, low=0.0, high=20.0,
                  doc="gap acceptance at junctions on the route: the ego goes when other traffic reaches "
                      "the conflict zone at least this long after the ego has left it (0: off)"),
        ParamSpec("pass_oncoming", None, kind="word", default="on", choices=("on", "off"),
                  doc="pass a standing or slow obstacle through the oncoming lane when the lane is seen "
                      "clear for the whole manoeuvre (off: never)"),
        ParamSpec("synthetic_objects", None, kind="int", default=0, low=0, high=500,
                  doc="extra objects perception reports in every frame (vehicles keeping pace beside "
                      "the road, 12 m or more to either side): a controllable workload for latency "
                      "studies, as the paper synthesises objects"),
    )
    nodes = {
        "perception": GROUND_TRUTH_SITES,
        "tracker": TRACKER_SITES,
        "planner": PLANNER_SITES,
        "control": CONTROL_SITES,
    }
    # Stored state a bit flip stays in (`bitflip` only; a node target draws these too).
    state_nodes = {
        "tracker": TRACKER_STATE_SITES,
        "planner": PLANNER_STATE_SITES,
    }
    doc = ("BEV-style stack: lidar, camera or surround-camera BEV perception, CV tracker, lattice planner, "
           "PID + pure pursuit.")

    @classmethod
    def required_sensors(cls, settings: dict) -> set[str]:
        """Sensor keywords the ego must carry for these settings (the compiler checks)."""
        mode = PERCEPTIONS.get(str(settings.get("perception", "ground_truth")))
        return {mode.needs_sensor} if mode is not None and mode.needs_sensor else set()

    @classmethod
    def frame_cost(cls, settings: dict) -> tuple[str, float] | None:
        """(sensor keyword, wall seconds per frame of it) that these settings' perception
        adds to the cost model's estimate (a network's inference); None: nothing."""
        mode = PERCEPTIONS.get(str(settings.get("perception", "ground_truth")))
        if mode is None or not mode.frame_cost_s:
            return None
        sensor = mode.expects[0] if mode.expects else mode.needs_sensor or "lidar"
        return sensor, mode.frame_cost_s

    @classmethod
    def required_modules(cls, settings: dict) -> dict[str, str]:
        """Setting → package outside the core install that these settings need."""
        mode = PERCEPTIONS.get(str(settings.get("perception", "ground_truth")))
        return {"perception": mode.requires} if mode is not None and mode.requires else {}

    @classmethod
    def sensor_mismatches(cls, settings: dict, sensor: str, values: dict) -> list[tuple[str, float]]:
        """(setting, expected value) where the ego's `sensor` (its settings, SI, defaults
        filled in) differs from what these stack settings are made for."""
        mode = PERCEPTIONS.get(str(settings.get("perception", "ground_truth")))
        if mode is None or mode.expects is None or mode.expects[0] != sensor:
            return []
        return [(key, want) for key, want in mode.expects[1].items()
                if key in values and not math.isclose(values[key], want, rel_tol=1e-9, abs_tol=1e-12)]

    @classmethod
    def fault_sites(cls, settings: dict | None = None) -> set[str]:
        """Fault targets of this stack; with `perception learned` or `camera_bev`, also the
        network's tensor sites `perception.<layer>` (all modes' when `settings` is not given)."""
        sites = {site for node, sites in cls.nodes.items() if node != "perception" for site in sites}
        for name, mode in PERCEPTIONS.items():
            if settings is None or settings.get("perception", "ground_truth") == name:
                sites |= set(mode.sites)
        for mode, tensor_sites in PERCEPTION_TENSOR_SITES.items():
            if settings is None or settings.get("perception") == mode:
                sites |= set(tensor_sites)
        return sites


# ---------------------------------------------------------------- external

# Settings the client keeps: never sent to the remote as stack settings.
CLIENT_SETTINGS = ("address", "timeout", "sites", "protocol", "answer")
SITE_STACKS = ("bev", "none")  # registered stacks whose fault sites a remote may declare
# The package a protocol's client imports outside the core install (addt_dsl.extras).
PROTOCOL_MODULES = {"osi": "osi3"}


@STACKS.register
class ExternalStack:
    """A stack in another process behind the bridge; the remote's own settings pass through."""

    keyword = "external"
    # Settings of the default stack pass through to the remote (the reference server
    # hosts `bev`); a user's stack reads what it understands.
    params = (
        ParamSpec("address", None, kind="string", default="127.0.0.1:5555",
                  doc="HOST:PORT of the remote stack's bridge server"),
        ParamSpec("timeout", units.TIME, default=30.0, low=0.001, high=3600.0,
                  doc="wall-clock wait for each reply before the run is marked detected"),
        ParamSpec("protocol", None, kind="word", default="bridge", choices=("bridge", "osi"),
                  doc="what the remote speaks: bridge (this project's JSON messages with the sensor frames) or "
                      "osi (ASAM OSI: a SensorView per step, answered by a MotionRequest or TrafficUpdate)"),
        ParamSpec("answer", None, kind="word", default="motion_request", choices=("motion_request", "traffic_update"),
                  doc="protocol osi: what the stack answers each SensorView with: motion_request (a desired "
                      "state or trajectory the twin's dynamics follow) or traffic_update (the host's new state)"),
        ParamSpec("sites", None, kind="word", default="bev", choices=SITE_STACKS,
                  doc="whose fault sites the remote stack has: bev (the reference server's: stack-internal "
                      "faults are checked against `stack bev` and sent to the remote in protocol 2) or "
                      "none (a stack without them: such faults are compile errors)"),
        *BevStack.params,
    )
    nodes = {name: () for name in NODE_NAMES}
    doc = "A stack in another process or language, lock-step over a socket (docs/bridge.md)."

    @classmethod
    def setting_problems(cls, settings: dict) -> dict[str, str]:
        """Settings the compiler refuses (E0204): an address that is not HOST:PORT with a
        port in 1-65535 and a host name, IPv4 or bracketed IPv6 address (`port 99999` was
        wrapped to 34463, `[::1]` passed the loopback check and could not resolve)."""
        address = settings.get("address")
        if not isinstance(address, str):
            return {}
        try:
            parse_address(address)
        except ValueError as exc:
            return {"address": str(exc)}
        return {}

    @classmethod
    def sites_of(cls, settings: dict | None = None):
        """The registered stack whose fault sites the remote has (`sites bev`), or None
        (`sites none`, or `protocol osi`, whose messages carry no faults): the compiler
        checks stack-internal fault targets against it."""
        name = str((settings or {}).get("sites", "bev"))
        if name == "none" or (settings or {}).get("protocol") == "osi":
            return None
        return STACKS.get(name)

    @classmethod
    def no_sites_reason(cls, settings: dict | None = None) -> tuple[str, str]:
        """(why, what to do) for a stack-internal fault the remote cannot take (E0109)."""
        if (settings or {}).get("protocol") == "osi":
            return ("`stack external protocol osi` cannot apply it: OSI's messages carry no fault schedule, "
                    "and an OSI stack reports no injections back",
                    "sensor faults (drop, delay, skew, shift, noise) act on the SensorViews sent; for "
                    "stack-internal faults serve the stack over `protocol bridge` with `sites bev` "
                    "(docs/bridge.md)")
        return ("`stack external sites none` declares none",
                "the reference server (python -m addt_dsl.stack.bridge_server) has the sites of "
                "`stack bev`: `sites bev` (the default) checks targets against them and sends the "
                "faults to the remote (bridge protocol 2, docs/bridge.md)")

    @classmethod
    def required_sensors(cls, settings: dict) -> set[str]:
        """`protocol osi` builds each SensorView on a lidar frame (what it saw, when)."""
        return {"lidar"} if settings.get("protocol") == "osi" else set()

    @classmethod
    def required_modules(cls, settings: dict) -> dict[str, str]:
        module = PROTOCOL_MODULES.get(str(settings.get("protocol", "bridge")))
        return {"protocol": module} if module else {}

    @classmethod
    def fault_sites(cls, settings: dict | None = None) -> set[str]:
        """The remote's scalar and tensor fault sites, as `sites` declares them."""
        stack_cls = cls.sites_of(settings)
        if stack_cls is None:
            return set()
        if settings is None:
            return stack_cls.fault_sites()
        return stack_cls.fault_sites({k: v for k, v in settings.items() if k not in CLIENT_SETTINGS})
