"""Fault kinds' specs: keyword, target kind (sensor, stack site or node), settings, docs and
the compile-time target check (`valid_targets`); the injections are in
`addt_dsl/runtime/faults/` (one module per family: temporal, spatial, image, compute, timing).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from addt_dsl import units
from addt_dsl.registry import FAULTS, ParamSpec

FIELD_NAMES = ("any", "sign", "exponent", "mantissa")  # IEEE-754 fields a flipped bit is drawn from
_AXES = ("x", "y", "z", "roll", "pitch", "yaw")
# Which camera of a rig: every one (-1), or camera k (k counted from the one looking along
# the mount's yaw, as `camera_rig` spreads them). A plain `camera` has one: lens 0.
LENS = ParamSpec("lens", None, kind="int", default=-1, low=-1, high=11,
                 doc="camera_rig only: the camera whose image is corrupted (0 = the one along the "
                     "mount's yaw, counting round as the rig spreads them; -1: every camera)")


class FaultSpec:
    keyword = ""
    target_kind = "sensor"  # "sensor" | "site" (a stack variable/output/tensor) | "node"
    # For sensor faults: the sensor keywords the kind applies to (None: any sensor).
    sensor_kinds: tuple[str, ...] | None = None
    params: tuple[ParamSpec, ...] = ()
    doc = ""
    # A setting whose negative default means "drawn from the fault's seed", with every drawn
    # value recorded in the fault event under the same name (bitflip: `bit`). The search
    # pins it to the value the run drew, then lowers it; it is never a magnitude.
    drawn_setting: str | None = None

    @classmethod
    def valid_targets(cls, sensors: Mapping[str, str], stack_cls) -> set[str]:
        """Targets this kind accepts, given the ego's sensors (name → keyword) and stack spec."""
        if cls.target_kind == "sensor":
            return {n for n, kw in sensors.items() if cls.sensor_kinds is None or kw in cls.sensor_kinds}
        if stack_cls is None:
            return set()
        if cls.target_kind == "node":
            return set(stack_cls.nodes)
        return set(stack_cls.fault_sites()) | set(getattr(stack_cls, "static_tensor_sites", lambda: ())())


class ImageFaultSpec(FaultSpec):
    sensor_kinds = ("camera", "camera_rig")

    @classmethod
    def setting_problems(cls, settings: dict, sensor_keyword: str, sensor_settings: dict) -> dict[str, str]:
        """{setting: why it is wrong} for settings that do not fit the target sensor."""
        lens = settings.get("lens", -1)
        if lens in (-1, 0) and sensor_keyword != "camera_rig":
            return {}
        if sensor_keyword != "camera_rig":
            return {"lens": "a `camera` has one image, lens 0; `lens K` picks camera K of a `camera_rig`"}
        if lens == -1:
            return {}
        cameras = int(sensor_settings["cameras"])
        if lens >= cameras:
            return {"lens": f"the rig has {cameras} camera(s), numbered 0 to {cameras - 1}"}
        return {}


@FAULTS.register
class Drop(FaultSpec):
    keyword = "drop"
    params = (
        ParamSpec("rate", units.DIMENSIONLESS, default=1.0, low=0.0, high=1.0,
                  doc="probability that a frame starts a drop event (Bernoulli), e.g. `5 %`"),
        ParamSpec("burst", None, kind="int", default=1, low=1, high=1000,
                  doc="consecutive frames lost per drop event"),
    )
    doc = ("Sensor frames are lost: each frame starts a drop event with probability `rate`; an "
           "event loses `burst` consecutive frames. Recorded per lost frame: `value` is the "
           "frame's timestamp [s].")

@FAULTS.register
class Delay(FaultSpec):
    keyword = "delay"
    params = (
        ParamSpec("by", units.TIME, required=True, low=0.0, high=10.0, doc="added transport delay"),
        ParamSpec("jitter", units.TIME, default=0.0, low=0.0, high=10.0, doc="uniform extra delay in [0, jitter]"),
    )
    doc = ("Frames arrive late by `by` plus a uniform jitter. A frame older than the stack's "
           "stale-input threshold (`stack bev stale`) on arrival is discarded by the stack: an "
           "effective drop, as in the paper. Recorded per frame: `value` is the delay [s].")

@FAULTS.register
class Skew(FaultSpec):
    keyword = "skew"
    params = (ParamSpec("by", units.TIME, required=True, low=-10.0, high=10.0, doc="timestamp offset"),)
    doc = ("Frame timestamps are wrong by a fixed offset (the data itself is on time). A "
           "negative skew makes frames look old, so the stack may discard them as stale. "
           "Recorded per frame: `value` is the stamped time [s].")


@FAULTS.register
class Shift(FaultSpec):
    keyword = "shift"
    params = tuple(ParamSpec(a, units.LENGTH if a in "xyz" else units.ANGLE, default=0.0,
                             low=-10.0 if a in "xyz" else -math.pi, high=10.0 if a in "xyz" else math.pi,
                             doc=f"{a} offset of the actual mount from the calibrated one")
                   for a in _AXES) + (
        ParamSpec("ramp", units.TIME, default=0.0, low=0.0, doc="drift: reach the full shift over this time"),)
    doc = ("The sensor's mount moves (a sudden shift, or a linear drift reaching the full shift "
           "after `ramp`) while the stack keeps the calibrated extrinsics, so detections are "
           "misplaced more the farther away they are. The shift stays after the window opens "
           "(a mount does not move back). Recorded when it starts and when a drift completes: "
           "`value` is the offset per axis [m, rad].")

@FAULTS.register
class Noise(FaultSpec):
    keyword = "noise"
    sensor_kinds = ("lidar", "gnss")
    params = (
        ParamSpec("range", units.LENGTH, default=0.0, low=0.0, high=50.0,
                  doc="lidar: Gaussian range noise per return (1 sigma)"),
        ParamSpec("dropout", units.DIMENSIONLESS, default=0.0, low=0.0, high=1.0,
                  doc="lidar: fraction of returns lost (independently per point)"),
        ParamSpec("position", units.LENGTH, default=0.0, low=0.0, high=1000.0,
                  doc="gnss: Gaussian position noise added to x and y (1 sigma)"),
    )
    doc = ("Additive sensor noise during the window. Lidar: each return's range gets Gaussian "
           "noise (`range`) and returns are lost with probability `dropout` (an object with "
           "fewer returns than the perception's minimum is missed). GNSS: Gaussian noise on the "
           "position fix. Recorded per frame: `value` is the RMS range error [m] and the number "
           "of returns lost (lidar) or the position error [m] (gnss).")


@FAULTS.register
class Blur(ImageFaultSpec):
    keyword = "blur"
    params = (
        ParamSpec("sigma", None, kind="number", default=2.0, low=0.0, high=100.0,
                  doc="Gaussian blur standard deviation [px] (0: none)"),
        ParamSpec("motion", None, kind="number", default=0.0, low=0.0, high=500.0,
                  doc="motion blur length [px] along `angle` (0: none)"),
        ParamSpec("angle", None, kind="number", default=0.0, low=-360.0, high=360.0,
                  doc="direction of the motion blur [deg in the image, 0 = horizontal]"),
        LENS,
    )
    doc = ("Camera image blur during the window: Gaussian defocus (`sigma` px) and/or linear "
           "motion blur (`motion` px at `angle`). Recorded per frame: `value` is sigma [px].")

@FAULTS.register
class ImageNoise(ImageFaultSpec):
    keyword = "image_noise"
    params = (
        ParamSpec("sigma", None, kind="number", default=10.0, low=0.0, high=255.0,
                  doc="additive Gaussian noise [8-bit intensity levels] (1 sigma)"),
        ParamSpec("salt", None, kind="number", default=0.0, low=0.0, high=1.0,
                  doc="fraction of pixels set to black or white (salt and pepper)"),
        LENS,
    )
    doc = ("Camera sensor noise during the window: additive Gaussian noise per pixel and channel "
           "(`sigma` in 8-bit levels; scaled to 1/255 for float images) and salt-and-pepper "
           "pixels. The Gaussian field is drawn once per fault and used at a random offset and "
           "sign each frame (cheap, and different every frame). Recorded per frame: `value` is "
           "sigma, `pixels` the number of salt/pepper pixels.")

@FAULTS.register
class Occlude(ImageFaultSpec):
    keyword = "occlude"
    params = (
        ParamSpec("fraction", None, kind="number", default=0.2, low=0.0, high=1.0,
                  doc="fraction of the image area covered"),
        ParamSpec("patches", None, kind="int", default=1, low=1, high=100,
                  doc="number of rectangular patches sharing that area"),
        ParamSpec("value", None, kind="number", default=0.0, low=0.0, high=255.0,
                  doc="patch intensity [8-bit levels] (0: black, e.g. dirt or tape on the lens)"),
        LENS,
    )
    doc = ("Part of the camera image is covered (dirt, a sticker, a wiper) by `patches` "
           "rectangles covering `fraction` of the area. Where the patches sit is drawn once from "
           "the fault's seed and stays fixed during the window (on a `camera_rig`, each camera's "
           "patches are drawn the first time it is corrupted). Recorded per frame: `value` is "
           "the covered fraction, `location` the sensor (`camera_rig.K` for camera K of a rig), "
           "`boxes` the patches (x0, y0, x1, y1 px).")


@FAULTS.register
class BitFlip(FaultSpec):
    keyword = "bitflip"
    target_kind = "site"
    drawn_setting = "bit"
    params = (
        ParamSpec("count", None, kind="int", default=1, low=0, high=10000, neutral=1,
                  doc="number of flips in the window (0: none, a fault-free baseline in the same grid)"),
        ParamSpec("bit", None, kind="int", default=-1, low=-1, high=63,
                  doc="bit index, 0 = least significant (-1: drawn from `field`)"),
        ParamSpec("field", None, kind="word", default="any", choices=FIELD_NAMES,
                  doc="IEEE-754 field the random bit is drawn from"),
        ParamSpec("tensor", None, kind="word", default="weights", choices=("weights", "activations"),
                  doc="for tensor sites: weights (persistent) or activations (one inference)"),
    )
    doc = ("Flip bits, as a radiation-induced or marginal-hardware fault would. `count` flips "
           "happen at instants drawn from the fault's seed inside the window (all at the instant "
           "for `at`). On a scalar site (`control.steer`) each flip inverts one bit of the "
           "float64 value passing through the site at or after its instant (transient: the "
           "next value is clean unless the node keeps it as state, like `control.integral`). "
           "On a node (`control`) each flip goes to one of the node's sites, drawn uniformly. "
           "On a tensor site of a learned model (`perception.backbone_0`) each flip inverts one "
           "bit of one element of the layer's weights (`tensor weights`, persistent) or of its "
           "output in one inference (`tensor activations`). On a state site (`planner.trajectory`, "
           "`tracker.tracks`) each flip inverts one bit of one element of the node's stored state, "
           "drawn uniformly, when the node next reads it: it persists until the node overwrites it. "
           "Recorded per flip: `location` (site, `site:element`, or `layer:param[index]`), `value` "
           "(after), `before`, `bit`.")
    @classmethod
    def valid_targets(cls, sensors, stack_cls):
        if stack_cls is None:
            return super().valid_targets(sensors, stack_cls)
        state = {s for sites in getattr(stack_cls, "state_nodes", {}).values() for s in sites}
        return super().valid_targets(sensors, stack_cls) | set(stack_cls.nodes) | state

@FAULTS.register
class StuckAt(FaultSpec):
    keyword = "stuck"
    target_kind = "site"
    params = (ParamSpec("value", None, kind="number", default=0.0, doc="value the site is stuck at (SI)"),)
    doc = ("A variable or output is stuck at a value during the window. Recorded when the site "
           "starts to hold the stuck value (and again after the true value has matched it): "
           "`value` is the stuck value, `before` the true one.")

@FAULTS.register
class RandomValue(FaultSpec):
    keyword = "random_value"
    target_kind = "site"
    params = (ParamSpec("low", None, kind="number", default=-1.0, doc="lower bound (SI)"),
              ParamSpec("high", None, kind="number", default=1.0, doc="upper bound (SI)"))
    doc = ("A variable or output takes uniform random values in [low, high] during the window. "
           "Recorded as one series event per site: `times`, `value` (the random values) and "
           "`before` (the true ones) are parallel lists, one entry per injected value.")


@FAULTS.register
class Spike(FaultSpec):
    keyword = "spike"
    target_kind = "node"
    params = (ParamSpec("by", units.TIME, required=True, low=0.0, high=10.0, doc="added latency"),)
    doc = ("A node's outputs are published later by a fixed amount during the window (e.g. a "
           "preempted process). Recorded per publication: `value` is the added latency [s].")

@FAULTS.register
class Slow(FaultSpec):
    keyword = "slow"
    target_kind = "node"
    params = (ParamSpec("factor", None, kind="number", default=2.0, low=1.0, high=1000.0,
                        doc="latency scale factor"),)
    doc = ("A node runs slower (thermal throttling, a contended core): its latency is multiplied "
           "by `factor` during the window. Recorded per publication: `value` is the added latency [s].")
