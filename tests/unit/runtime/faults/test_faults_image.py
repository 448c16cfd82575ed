"""Camera image corruptions on synthetic frames (the camera sensor's contract: H×W×3 arrays)."""

import numpy as np
import pytest
from tests.unit.runtime.faults.faultkit import camera_frame, lidar_frame, one


def _sharpness(img):
    import cv2

    return float(cv2.Laplacian(img.astype(np.float32).mean(axis=2), cv2.CV_32F).var())


@pytest.mark.parametrize("dtype", [np.uint8, np.float32])
def test_blur_softens_edges_keeps_shape_and_dtype_and_never_edits_the_input(dtype):
    kind, events = one("blur", target="camera", sigma=2.0)
    frame = camera_frame(dtype=dtype)
    original = frame.data["image"].copy()
    out, delay = kind.on_frame(frame, 0.0)
    img = out.data["image"]
    assert img.shape == original.shape and img.dtype == original.dtype and delay == 0.0
    assert (frame is out) and (original == camera_frame(dtype=dtype).data["image"]).all()
    assert _sharpness(img) < 0.3 * _sharpness(original)
    assert abs(float(img.mean()) - float(original.mean())) < 0.02 * (255 if dtype == np.uint8 else 1)
    assert events[0].detail["location"] == "camera" and events[0].detail["value"] == 2.0


def test_motion_blur_smears_along_its_direction_only():
    from addt_dsl.runtime.sensors import Frame

    kind, _ = one("blur", target="camera", sigma=0.0, motion=9, angle=0)
    stripes = ((np.arange(64) // 8) % 2 * 200).astype(np.uint8)
    vertical = np.broadcast_to(stripes[None, :, None], (48, 64, 3)).copy()  # edges across x
    horizontal = np.broadcast_to(stripes[:48, None, None], (48, 64, 3)).copy()  # edges across y
    # Gradient energy: a box blur spreads a step over its length, dividing the energy by it.
    energy = lambda a, axis: float((np.diff(a.astype(np.float32), axis=axis) ** 2).sum())  # noqa: E731
    v = kind.on_frame(Frame("camera", 0.0, {"image": vertical}), 0.0)[0].data["image"]
    h = kind.on_frame(Frame("camera", 0.0, {"image": horizontal}), 0.0)[0].data["image"]
    assert energy(v, 1) < 0.2 * energy(vertical, 1)  # horizontal motion blurs vertical edges
    assert (h == horizontal).all()  # and leaves horizontal edges alone


def test_zero_blur_is_the_identity():
    kind, _ = one("blur", target="camera", sigma=0.0, motion=0.0)
    assert (kind.on_frame(camera_frame(), 0.0)[0].data["image"] == camera_frame().data["image"]).all()


def test_image_noise_has_the_requested_sigma_and_is_clipped():
    kind, events = one("image_noise", target="camera", sigma=6.0, seed=3)
    frame = camera_frame(96, 128)
    clean = frame.data["image"].astype(np.float64)
    noisy = kind.on_frame(frame, 0.0)[0].data["image"]
    assert noisy.dtype == np.uint8
    diff = noisy.astype(np.float64) - clean
    assert np.std(diff) == pytest.approx(6.0, rel=0.08)
    assert events[0].detail["value"] == 6.0


def test_image_noise_scales_to_float_images():
    kind, _ = one("image_noise", target="camera", sigma=25.5, seed=3)
    frame = camera_frame(96, 128, dtype=np.float32)
    clean = frame.data["image"].astype(np.float64)
    noisy = kind.on_frame(frame, 0.0)[0].data["image"]
    inside = (clean > 0.35) & (clean < 0.65)  # away from the clipping bounds
    assert np.std((noisy - clean)[inside]) == pytest.approx(0.1, rel=0.1)
    assert noisy.min() >= 0.0 and noisy.max() <= 1.0


def test_salt_and_pepper_fraction():
    kind, events = one("image_noise", target="camera", sigma=0.0, salt=0.1, seed=4)
    out = kind.on_frame(camera_frame(100, 100), 0.0)[0].data["image"]
    extreme = np.all(out == 0, axis=2) | np.all(out == 255, axis=2)
    assert 0.08 < extreme.mean() < 0.12
    assert events[0].detail["pixels"] == pytest.approx(1000, rel=0.15)


def test_occlusion_covers_the_fraction_with_patches_fixed_over_time():
    kind, events = one("occlude", target="camera", fraction=0.25, patches=3, value=0, seed=8)
    masks = []
    for t in (0.0, 0.1, 0.2):
        frame = camera_frame(120, 160)
        frame.data["image"][:] = 200
        out = kind.on_frame(frame, t)[0].data["image"]
        masks.append(np.all(out == 0, axis=2))
    assert (masks[0] == masks[1]).all() and (masks[1] == masks[2]).all()
    assert 0.15 < masks[0].mean() <= 0.26  # patches may overlap
    assert events[0].detail["value"] == pytest.approx(masks[0].mean())
    assert len(events[0].detail["boxes"]) == 3


def test_occlusion_placement_depends_on_the_fault_seed():
    a = one("occlude", target="camera", fraction=0.1, seed=1)[0].on_frame(camera_frame(), 0)[0].data["image"]
    b = one("occlude", target="camera", fraction=0.1, seed=2)[0].on_frame(camera_frame(), 0)[0].data["image"]
    c = one("occlude", target="camera", fraction=0.1, seed=1)[0].on_frame(camera_frame(), 0)[0].data["image"]
    assert (a == c).all() and (a != b).any()


@pytest.mark.parametrize("kind_name", ["blur", "image_noise", "occlude"])
def test_frames_without_an_image_pass_unchanged(kind_name):
    kind, events = one(kind_name, target="camera")
    frame = lidar_frame(10)
    out, _ = kind.on_frame(frame, 0.0)
    assert out is frame and "image" not in out.data and not events


def test_image_noise_differs_from_frame_to_frame():
    kind, _ = one("image_noise", target="camera", sigma=10.0, seed=5)
    a = kind.on_frame(camera_frame(), 0.0)[0].data["image"].astype(int)
    b = kind.on_frame(camera_frame(), 0.1)[0].data["image"].astype(int)
    clean = camera_frame().data["image"].astype(int)
    assert np.corrcoef((a - clean).ravel(), (b - clean).ravel())[0, 1] < 0.2


def _rig_frame(cameras: int = 4):
    from addt_dsl.runtime.sensors import Frame

    images = np.stack([camera_frame(24, 32).data["image"] // (k + 1) for k in range(cameras)])
    return Frame("camera_rig", 0.0, {"images": images, "intrinsics": np.eye(3)})


@pytest.mark.parametrize("kind,settings", [("blur", {"sigma": 2.0}), ("image_noise", {"sigma": 20.0}),
                                           ("occlude", {"fraction": 0.5})])
def test_a_rig_fault_corrupts_every_camera_by_default_and_one_camera_with_lens(kind, settings):
    frame = _rig_frame()
    original = frame.data["images"].copy()
    fault, events = one(kind, target="camera_rig", seed=5, **settings)
    every = fault.on_frame(frame, 0.0)[0].data["images"]
    assert (frame.data["images"] is not original) and (_rig_frame().data["images"] == original).all()
    assert every.shape == original.shape and every.dtype == original.dtype
    assert all((every[k] != original[k]).any() for k in range(4))
    assert [e.detail["location"] for e in events] == [f"camera_rig.{k}" for k in range(4)]

    fault, events = one(kind, target="camera_rig", seed=5, lens=2, **settings)
    picked = fault.on_frame(_rig_frame(), 0.0)[0].data["images"]
    assert [k for k in range(4) if (picked[k] != original[k]).any()] == [2]
    assert [e.detail["location"] for e in events] == ["camera_rig.2"]


def test_occlusion_on_a_rig_places_each_lens_patches_once():
    fault, events = one("occlude", target="camera_rig", seed=2, fraction=0.3, patches=2)
    for t in (0.0, 0.1, 0.2):
        fault.on_frame(_rig_frame(3), t)
    boxes = {}
    for e in events:
        boxes.setdefault(e.detail["location"], []).append(e.detail["boxes"])
    assert sorted(boxes) == ["camera_rig.0", "camera_rig.1", "camera_rig.2"]
    assert all(len({str(b) for b in seen}) == 1 for seen in boxes.values())  # fixed on each lens
    assert len({str(seen[0]) for seen in boxes.values()}) > 1  # drawn per lens, not shared


def test_lens_is_checked_against_the_target_sensor():
    from addt_dsl.registry import FAULTS

    occlude = FAULTS.get("occlude")
    assert occlude.setting_problems({"lens": -1}, "camera", {}) == {}
    assert occlude.setting_problems({"lens": 3}, "camera_rig", {"cameras": 6}) == {}
    assert "numbered 0 to 5" in occlude.setting_problems({"lens": 6}, "camera_rig", {"cameras": 6})["lens"]
    assert occlude.setting_problems({"lens": 0}, "camera", {"width": 320}) == {}  # its one image
    assert "camera_rig" in occlude.setting_problems({"lens": 1}, "camera", {"width": 320})["lens"]


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("shape", [(48, 64), (120, 160), (40, 128)])
def test_occlusion_covers_the_fraction_asked_for_whatever_the_drawn_aspect(seed, shape):
    from addt_dsl.runtime.sensors import Frame

    h, w = shape
    image = np.full((h, w, 3), 200, np.uint8)
    for fraction in (1.0, 0.9, 0.5):
        fault, events = one("occlude", target="camera", seed=seed, fraction=fraction)
        fault.on_frame(Frame("camera", 0.0, {"image": image}), 0.0)
        # One patch: its area is the fraction, up to rounding to whole pixels.
        assert events[0].detail["value"] == pytest.approx(fraction, abs=2.0 / min(h, w))
