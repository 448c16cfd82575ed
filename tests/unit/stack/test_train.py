"""Training is reproducible from the seed (same seed and thread count: same weights, bit for bit)."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytestmark = pytest.mark.torch

from addt_dsl.stack.train import train  # noqa: E402


def _weights(seed):
    model, _ = train(seed=seed, scenes=48, epochs=1, batch=16, threads=1, lr=1e-3, log=lambda *_: None)
    return model.state_dict()


def test_same_seed_same_weights_other_seed_other_weights():
    a, b, c = _weights(3), _weights(3), _weights(4)
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert any(not torch.equal(a[k], c[k]) for k in a)


def test_lidar_vfov_reaches_the_scans_and_the_weights_meta(tmp_path):
    import math

    import numpy as np

    from addt_dsl.stack.synth import generate
    from addt_dsl.stack.train import main

    samples = generate(3, 0, lidars=("360x3",), lidar_settings={"vfov": math.radians(4.0)})
    for s in samples:  # sensor 1 m up: beams at -2, 0, +2 deg
        rel = s.points - np.array([s.sensor_xy[0], s.sensor_xy[1], 1.0])
        elevation = np.degrees(np.arctan2(rel[:, 2], np.hypot(rel[:, 0], rel[:, 1])))
        assert np.abs(elevation).max() < 2.0 + 1e-3 and np.abs(elevation).max() > 1.9
    out = tmp_path / "w.pt"
    assert main(["--scenes", "16", "--epochs", "1", "--batch", "8", "--lidars", "360x3", "--lidar-p", "1",
                 "--lidar-vfov", "4", "--out", str(out)]) == 0
    meta = torch.load(out, weights_only=True)["meta"]
    assert meta["lidar_vfov_deg"] == 4.0 and meta["lidars"] == ["360x3"]


def test_init_fine_tunes_from_a_weights_file(tmp_path):
    """`--init`: training starts from the file's weights (lr 0 leaves them as they are) and
    the meta says where from; without it, from fresh ones."""
    from addt_dsl.stack.learned import load_weights
    from addt_dsl.stack.train import main

    base = tmp_path / "base.pt"
    assert main(["--scenes", "16", "--epochs", "1", "--batch", "8", "--widths", "8", "12", "16",
                 "--threads", "1", "--out", str(base)]) == 0
    start, base_meta = load_weights(base)
    frozen = tmp_path / "frozen.pt"
    assert main(["--scenes", "16", "--epochs", "1", "--batch", "8", "--lr", "0", "--seed", "5",
                 "--init", str(base), "--threads", "1", "--out", str(frozen)]) == 0
    blob = torch.load(frozen, weights_only=True)
    assert all(torch.equal(start[k], blob["state_dict"][k]) for k in start)
    meta = blob["meta"]
    assert meta["widths"] == [8, 12, 16] and meta["init"]["meta"]["seed"] == base_meta["seed"]
    assert meta["train_s_total"] >= meta["train_s"] and "--init" in meta["command"]
    moved, _ = train(seed=5, scenes=16, epochs=1, batch=8, threads=1, lr=1e-3, log=lambda *_: None, init=base)
    assert any(not torch.equal(start[k], v) for k, v in moved.state_dict().items())


def test_class_weights_scale_each_objects_class_loss():
    from addt_dsl.stack.train import centernet_loss

    torch.manual_seed(0)
    heat = torch.randn(1, 1, 4, 4)
    box = torch.randn(1, 10, 4, 4)
    reg = torch.zeros(1, 7, 4, 4)
    mask = torch.zeros(1, 4, 4)
    heat_t = torch.zeros(1, 4, 4)
    for (i, j), cls in (((0, 0), 3), ((2, 3), 2)):
        heat_t[0, i, j] = mask[0, i, j] = 1.0
        reg[0, 6, i, j] = cls
    plain = centernet_loss(heat, box, heat_t, reg, mask)[1][4]
    same = centernet_loss(heat, box, heat_t, reg, mask, class_weight=torch.ones(4))[1][4]
    ce = torch.nn.functional.cross_entropy(box[0, 6:, [0, 2], [0, 3]].T, torch.tensor([3, 2]), reduction="none")
    weighted = centernet_loss(heat, box, heat_t, reg, mask, class_weight=torch.tensor([1.0, 1.0, 1.0, 3.0]))[1][4]
    assert same == plain
    assert abs(plain - ce.sum().item() / 2) < 1e-6
    assert abs(weighted - (3 * ce[0] + ce[1]).item() / 2) < 1e-6


def test_cyclists_per_scene_leaves_the_default_scenes_alone():
    from addt_dsl.stack.bev_grid import CLASSES
    from addt_dsl.stack.synth import CYCLISTS_PER_SCENE, generate

    default = generate(6, 11)
    explicit = generate(6, 11, cyclists=CYCLISTS_PER_SCENE)
    assert all(np.array_equal(a.boxes, b.boxes) and np.array_equal(a.points, b.points)
               for a, b in zip(default, explicit))
    cyc = CLASSES.index("cyclist")
    few = sum(int((s.classes == cyc).sum()) for s in generate(20, 11, cyclists=0.0))
    many = sum(int((s.classes == cyc).sum()) for s in generate(20, 11, cyclists=4.0))
    assert few == 0 and many > 40


def test_epochs_0_with_init_only_offsets_the_class_logits(tmp_path):
    from addt_dsl.stack.bev_grid import BOX_CHANNELS
    from addt_dsl.stack.learned import load_weights
    from addt_dsl.stack.train import main

    base = tmp_path / "base.pt"
    assert main(["--scenes", "16", "--epochs", "1", "--batch", "8", "--widths", "8", "12", "16",
                 "--threads", "1", "--out", str(base)]) == 0
    start, _ = load_weights(base)
    out = tmp_path / "offset.pt"
    assert main(["--init", str(base), "--epochs", "0", "--class-logit-offsets", "0", "0", "0.5", "-1",
                 "--out", str(out)]) == 0
    blob = torch.load(out, weights_only=True)
    bias = blob["state_dict"]["head.box.bias"]
    assert torch.equal(bias[:BOX_CHANNELS], start["head.box.bias"][:BOX_CHANNELS])
    assert torch.allclose(bias[BOX_CHANNELS:] - start["head.box.bias"][BOX_CHANNELS:],
                          torch.tensor([0.0, 0.0, 0.5, -1.0]))
    assert all(torch.equal(v, start[k]) for k, v in blob["state_dict"].items() if k != "head.box.bias")
    meta = blob["meta"]
    assert meta["class_logit_offsets"] == [0.0, 0.0, 0.5, -1.0] and meta["scenes"] == 0 and meta["epochs"] == 0


def test_cluster_scenes_fit_the_class_reader_and_ship_it_with_the_weights(tmp_path):
    """`--cluster-scenes`: the cluster class reader is fitted to the detector's detections
    and stored beside its layers; the node loads it, and the same command gives the same trees."""
    from addt_dsl.stack.learned import WEIGHTS_PATH, LearnedPerception, load_cluster_classes
    from addt_dsl.stack.train import main

    outs = [tmp_path / "a.pt", tmp_path / "b.pt"]
    for out in outs:
        assert main(["--init", str(WEIGHTS_PATH), "--epochs", "0", "--cluster-scenes", "40", "--cluster-seed", "5",
                     "--cluster-logit-offsets", "0", "0", "0", "0.5", "--out", str(out)]) == 0
    blob = torch.load(outs[0], weights_only=True)
    assert blob["meta"]["cluster"]["scenes"] == 40 and blob["meta"]["cluster"]["logit_offsets"] == [0, 0, 0, 0.5]
    assert any(k.startswith("cluster.") for k in blob["state_dict"])
    (a, offsets), (b, _) = load_cluster_classes(outs[0]), load_cluster_classes(outs[1])
    assert offsets.tolist() == [0, 0, 0, 0.5]
    assert all(np.array_equal(u, v) for u, v in zip(a.state().values(), b.state().values()))
    node = LearnedPerception({}, weights=outs[0])
    assert node.cluster_classes is not None


def test_cluster_cyclists_put_more_cyclists_in_the_class_reader_scans(tmp_path):
    """`--cluster-cyclists MEAN`: the reader's scans have that many cyclists tried per scene
    (the detections it is fitted on count more of them), and the metadata says so."""
    from addt_dsl.stack.learned import WEIGHTS_PATH
    from addt_dsl.stack.train import main

    counts = {}
    for mean in ("1.2", "4"):
        out = tmp_path / f"c{mean}.pt"
        assert main(["--init", str(WEIGHTS_PATH), "--epochs", "0", "--cluster-scenes", "40", "--cluster-seed", "5",
                     "--cluster-cyclists", mean, "--out", str(out)]) == 0
        cluster = torch.load(out, weights_only=True)["meta"]["cluster"]
        assert cluster["cyclists"] == float(mean)
        counts[mean] = cluster["detections"]
    assert counts["4"][3] > 2 * counts["1.2"][3]
