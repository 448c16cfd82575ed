"""Tensor faults on the shipped detector: hooks only while a flip is pending, and the
in-place flips of `RegionForward` (`flip_owned`) record and compute exactly what the
clone-and-compare path does."""

from types import SimpleNamespace

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytestmark = pytest.mark.torch

from addt_dsl.plan import ConcreteFault  # noqa: E402
from addt_dsl.runtime.faults import FaultSchedule  # noqa: E402
from addt_dsl.runtime.faults.tensor import TensorFlipper  # noqa: E402
from addt_dsl.stack.learned import LearnedPerception  # noqa: E402
from addt_dsl.stack.synth import ScanGenerator  # noqa: E402

STEP_S = 0.01
LIDAR_EVERY = 10  # a frame every 10 steps (10 Hz)


@pytest.fixture(scope="module")
def frames():
    """A short drive past two vehicles: scans whose occupied region moves frame to frame."""
    gen = ScanGenerator(3)
    try:
        return [gen.scan([("car", 18.0 - 1.5 * i, -0.3, 0.01 * i), ("truck", -25.0 + i, 3.5, 0.0)])
                for i in range(12)]
    finally:
        gen.close()


def _run(frames, faults, duration_s=6.0):
    """Play the loop: the schedule's timers at each step start, a detection every lidar period.

    Returns (per-step hooked layers, fault events, head outputs of every frame, schedule).
    """
    node = LearnedPerception({})
    clock = SimpleNamespace(t=0.0)
    events = []
    sched = FaultSchedule([ConcreteFault(index=i, **f) for i, f in enumerate(faults)], STEP_S, duration_s, events)
    sched.bind(SimpleNamespace(tensor_sites=node.tensor_modules), lambda: clock.t)
    layers = node.tensor_modules()
    hooked, outputs = [], []
    try:
        for k in range(round(duration_s / STEP_S) + 1):
            clock.t = k * STEP_S
            if clock.t + 1e-12 >= sched.next_wake_s:
                sched.wake(clock.t)
            if k % LIDAR_EVERY == 0:
                s = frames[(k // LIDAR_EVERY) % len(frames)]
                node.detect(s.points, s.sensor_xy)
                maps = node._forward.maps
                outputs.append((maps["head.center"].buf.clone(), maps["head.box"].buf.clone()))
            hooked.append(sorted(n for n, m in layers.items() if m._forward_hooks or m._forward_pre_hooks))
    finally:
        sched.close()
    return hooked, [(e.time_s, e.detail) for e in events], outputs, sched


def _fault(target, start, end, seed=11, **settings):
    return dict(kind="bitflip", target=target, start_s=start, end_s=end, settings=settings, seed=seed)


@pytest.mark.parametrize("tensor", ["activations", "weights"])
def test_no_hook_is_registered_outside_the_flips(frames, tensor):
    fault = _fault("perception.backbone.conv1", 2.0, 3.0, tensor=tensor, count=3)
    hooked, events, _, sched = _run(frames, [fault])
    times = sched.kinds[0].times
    assert len(events) == 3
    # Taken at the first frame (every 0.1 s) at or after each instant.
    taken = [np.ceil(t / (STEP_S * LIDAR_EVERY) - 1e-9) * STEP_S * LIDAR_EVERY for t in times]
    assert [round(t, 9) for t, _ in events] == [round(t, 9) for t in taken]
    for k, names in enumerate(hooked):
        t = k * STEP_S
        pending = any(times[i] <= t + 1e-12 < taken[i] for i in range(len(times)))
        # A hook exactly while a flip is due but not yet taken by a forward pass.
        assert names == (["perception.backbone.conv1"] if pending else []), t
    assert not any(hooked[k] for k in range(int(times[0] / STEP_S)))  # nothing before the window
    assert not any(h for h in hooked[int(3.0 / STEP_S) + LIDAR_EVERY:])  # nothing after it
    assert sched.next_wake_s == float("inf")


@pytest.mark.parametrize("target, settings", [
    ("perception.backbone.conv0", {"count": 6, "field": "exponent"}),
    ("perception.neck.fine", {"count": 8}),
    ("perception.head.box", {"count": 5, "field": "sign"}),
    ("perception.backbone.conv2", {"count": 30, "bit": 30}),  # several flips per frame
])
def test_in_place_flips_match_the_clone_and_compare_method(frames, monkeypatch, target, settings):
    """Same seed: the same elements flipped, the same events and counts, and bit-identical
    head outputs frame after frame, whether RegionForward takes the flips in place
    (`flip_owned`) or, as before, runs the hook on a clone and compares whole maps."""
    faults = [_fault(target, 1.0, 4.0, tensor="activations", **settings),
              _fault("perception.neck.lateral", 1.5, 2.5, seed=4, tensor="activations", count=3, bit=31)]
    _, new_events, new_out, _ = _run(frames, faults)
    monkeypatch.setattr(TensorFlipper, "flip_owned", None)  # RegionForward falls back to clone + compare
    _, old_events, old_out, _ = _run(frames, faults)
    assert len(new_events) == settings["count"] + 3
    assert repr(new_events) == repr(old_events)  # repr: a flip to NaN gives NaN on both sides, and nan != nan
    for (h_new, b_new), (h_old, b_old) in zip(new_out, old_out, strict=True):
        assert torch.equal(h_new.view(torch.int32), h_old.view(torch.int32))
        assert torch.equal(b_new.view(torch.int32), b_old.view(torch.int32))
    clean = _run(frames, [])[2]
    assert any(not torch.equal(a[0], b[0]) or not torch.equal(a[1], b[1]) for a, b in zip(new_out, clean)) or \
        settings.get("field") == "sign"  # the flips reach the heads (a sign flip may vanish in a ReLU)


def test_a_flip_that_changes_nothing_leaves_no_changed_region():
    """An element flipped twice (the same bit) is back to its value: no changed cells, as a
    comparison of maps would find; a sign flip of 0.0 compares equal too."""
    from addt_dsl.stack.learned import EMPTY, RegionForward

    class Hook:
        def __init__(self, flips):
            self.flips = flips

        def flip_owned(self, buf):
            from addt_dsl.runtime.faults.tensor import flip_bit_

            return [(k, *flip_bit_(buf, k, bit)) for k, bit in self.flips]

        def __call__(self, module, inputs, output):  # RegionForward must use flip_owned
            raise AssertionError

    layer = torch.nn.Conv2d(1, 2, 1)
    buf = torch.zeros(1, 2, 4, 5)
    buf[0, 1, 2, 3] = 1.5
    layer.register_forward_hook(Hook([(2 * 20 - 7, 30), (2 * 20 - 7, 30), (0, 31)]))
    assert RegionForward._hooked(layer, buf, buf) == EMPTY
    layer2 = torch.nn.Conv2d(1, 2, 1)
    layer2.register_forward_hook(Hook([(20 + 2 * 5 + 3, 30), (6, 0)]))
    # Element 33: channel 1, row 2, column 3; element 6: channel 0, row 1, column 1.
    assert RegionForward._hooked(layer2, buf, buf) == (1, 3, 1, 4)


@pytest.mark.parametrize("target, settings", [
    ("perception.backbone.conv0", {"count": 12}),  # mostly kernel weights: the maps come out as before
    ("perception.backbone.conv0", {"count": 6, "field": "exponent"}),
    ("perception.neck.fuse", {"count": 8}),
    ("perception.head.box", {"count": 5, "field": "sign"}),
])
def test_weight_flips_recompute_only_what_changes_with_the_same_bits(frames, monkeypatch, target, settings):
    """A weight fault rebuilds the maps for an empty grid from the flipped layer on, and
    stops where a map comes out bit for bit as before; the head outputs, frame after
    frame, are those of recomputing every map at every rebuild."""
    from addt_dsl.stack import learned

    faults = [_fault(target, 0.5, 4.0, tensor="weights", **settings),
              _fault("perception.backbone.conv2", 2.0, 3.0, seed=5, tensor="weights", count=2, bit=31)]
    convs = []
    conv2d = learned.F.conv2d
    monkeypatch.setattr(learned.F, "conv2d", lambda *a, **k: convs.append(1) or conv2d(*a, **k))
    _, new_events, new_out, _ = _run(frames, faults)
    calls_new = len(convs)  # the same windows both ways (same outputs): the difference is the rebuilds'
    convs.clear()
    rebuild = learned.RegionForward._rebuild

    def rebuild_all(self):  # every map recomputed at every rebuild, as before
        self._last_backgrounds = {}
        rebuild(self)

    monkeypatch.setattr(learned.RegionForward, "_rebuild", rebuild_all)
    _, old_events, old_out, _ = _run(frames, faults)
    calls_old = len(convs)
    assert len(new_events) == settings["count"] + 2
    assert repr(new_events) == repr(old_events)
    for (h_new, b_new), (h_old, b_old) in zip(new_out, old_out, strict=True):
        assert torch.equal(h_new.view(torch.int32), h_old.view(torch.int32))
        assert torch.equal(b_new.view(torch.int32), b_old.view(torch.int32))
    assert calls_new < calls_old


def test_a_distant_flip_is_computed_apart_from_the_points(frames):
    """A flip far from the points is computed in its own boxes: the heads away from its
    reach keep the bits of the same frame without the flip (the points' windows are as
    without faults), and near it they match the dense network with the same flip."""
    node = LearnedPerception({})
    s = frames[0]
    node.detect(s.points, s.sensor_xy)
    clean = node._forward.maps["head.center"].buf.clone()
    site = "perception.backbone.conv1"
    shape = node.activation_shape(site)
    background = node._forward.maps["backbone.conv1"].background
    channel = int(torch.nonzero(background[0, :, 1, 1] > 0)[0])  # positive: the flipped value passes the ReLU
    index = int(np.ravel_multi_index((0, channel, 1, 1), shape))  # a corner: the scans' vehicles are far from it
    flip = node.flip_activation_bits(site, [index], [26])  # ×/÷ 2^8
    node.detect(s.points, s.sensor_xy)
    assert flip.fired[0] != flip.fired[1]
    flipped = node._forward.maps["head.center"].buf.clone()
    # conv1's cell (1, 1) is head cell (2, 2); the layers after it reach ~20 head cells.
    assert not torch.equal(flipped[..., :24, :24], clean[..., :24, :24])
    # Far from it, the values of the frame without the flip: bit for bit on most CPUs; on some
    # (Xeon with AVX-512) the box recompute's convolutions round differently, by ~1e-6 here.
    far, far_clean = flipped[..., 30:, :], clean[..., 30:, :]
    np.testing.assert_allclose(far.numpy(), far_clean.numpy(), rtol=0, atol=1e-5)
    node.flip_activation_bits(site, [index], [26])
    with torch.inference_mode():
        dense, _ = node.model(node._input)
    np.testing.assert_allclose(flipped.numpy(), dense.numpy(), rtol=1e-5, atol=2e-5)
    node.last_activation_flips, node._armed = [], []


def test_a_flip_the_relu_undoes_widens_nothing(frames):
    """A negative element of a pre-activation map flipped to another negative value is
    zero after the ReLU: the layers after it compute only the points' region, and the
    heads are bit for bit those of the frame without the flip."""
    node = LearnedPerception({})
    s = frames[0]
    node.detect(s.points, s.sensor_xy)
    clean = [node._forward.maps[k].buf.clone() for k in ("head.center", "head.box")]
    site = "perception.backbone.conv0"
    background = node._forward.maps["backbone.conv0"].background
    channel = int(torch.nonzero(background[0, :, 0, 0] < 0)[0])  # a channel whose empty-grid value is negative
    index = int(np.ravel_multi_index((0, channel, 2, 2), node.activation_shape(site)))
    seen = []
    widths = node._forward._windows

    def windows(name, x, regions, shape):
        seen.append(len(regions))
        return widths(name, x, regions, shape)

    node._forward._windows = windows
    node.flip_activation_bits(site, [index], [24])  # an exponent bit: still negative
    node.detect(s.points, s.sensor_xy)
    assert node.last_activation_flips and node.last_activation_flips[0][1][1][0] < 0
    assert max(seen[1:]) == 1  # after conv0's ReLU: one box, the points'
    for k, c in zip(("head.center", "head.box"), clean):
        assert torch.equal(node._forward.maps[k].buf.view(torch.int32), c.view(torch.int32))
