"""Fault injection: one registered class per DSL keyword, and the schedule that applies them.

Each fault has a target (a sensor, a stack fault site such as `control.steer`, a node,
or a tensor site of a learned model), a time window, settings and its own seed. The
kinds live in small modules by family; importing this package registers them all:

- `temporal`: drop, delay, skew                   (sensor frames)
- `spatial`:  shift, noise                        (sensor pose and data)
- `image`:    blur, image_noise, occlude          (camera images, opencv)
- `compute`:  bitflip, stuck, random_value        (stack variables, outputs, tensors)
- `timing`:   spike, slow                         (node latency)

See `base` for the hooks and the trace record every injection leaves.
"""

from addt_dsl.runtime.faults import compute, image, spatial, temporal, timing  # noqa: F401  (registers)
from addt_dsl.runtime.faults.base import (
    BIT_FIELDS_F64,
    IEEE_FIELDS,
    Binding,
    FaultKind,
    FaultSchedule,
    flip_float64_bit,
)
from addt_dsl.runtime.faults.compute import BitFlip, RandomValue, StuckAt
from addt_dsl.runtime.faults.image import Blur, ImageNoise, Occlude
from addt_dsl.runtime.faults.spatial import Noise, Shift
from addt_dsl.runtime.faults.temporal import Delay, Drop, Skew
from addt_dsl.runtime.faults.timing import Slow, Spike

__all__ = [
    "BIT_FIELDS_F64", "IEEE_FIELDS", "Binding", "BitFlip", "Blur", "Delay", "Drop", "FaultKind",
    "FaultSchedule", "ImageNoise", "Noise", "Occlude", "RandomValue", "Shift", "Skew", "Slow", "Spike",
    "StuckAt", "flip_float64_bit",
]
