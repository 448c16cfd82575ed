"""Bit flips in torch tensors: weights (persistent, undone at close) and activations (one inference).

The stack side of the interface is `tensor_sites() -> {name: torch.nn.Module}`; these tests
play the stack with a tiny model. CUDA cases run where a GPU is present.
"""

import struct
from types import SimpleNamespace

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytestmark = pytest.mark.torch

# No pydantic-based imports here (plan, schedule): this module also runs on the GPU machine,
# whose environment has torch and pytest but not the whole project's dependencies.
from addt_dsl.runtime.faults.base import Binding  # noqa: E402
from addt_dsl.runtime.faults.compute import BitFlip  # noqa: E402
from addt_dsl.runtime.faults.tensor import bit_range, flip_bit_, tensor_site_name, tensor_sites_of  # noqa: E402

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def tiny_model(device="cpu", dtype=torch.float32):
    torch.manual_seed(0)
    backbone = torch.nn.Sequential(torch.nn.Linear(6, 16), torch.nn.ReLU(), torch.nn.Linear(16, 8))
    model = torch.nn.Sequential()
    model.add_module("backbone", backbone)
    model.add_module("head", torch.nn.Linear(8, 3))
    return model.to(device=device, dtype=dtype).eval()


def _x(device="cpu", dtype=torch.float32):
    return torch.linspace(-1, 1, 12, dtype=dtype).reshape(2, 6).to(device)


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


class _Schedule:
    def __init__(self, kind):
        self.kind = kind

    def close(self):
        self.kind.close()


def _bind(model, target, clock, start=0.0, end=None, seed=1, **settings):
    """One `bitflip` fault on a tensor site of `model`, bound as the fault schedule binds it."""
    fault = SimpleNamespace(index=0, kind="bitflip", target=target, start_s=start, end_s=end,
                            settings=settings, seed=seed)
    events = []
    kind = BitFlip(fault, 0.01, 10.0, lambda t, detail: events.append(SimpleNamespace(time_s=t, detail=detail)))
    kind.bind(Binding(nodes={}, tensor_sites=tensor_sites_of(model, "perception"), clock=clock))
    return _Schedule(kind), kind, events


def test_site_names_are_dsl_names():
    assert tensor_site_name("perception", "backbone.0.conv") == "perception.backbone_0.conv"
    assert tensor_site_name("perception", "0") == "perception_0"
    assert tensor_site_name("perception", "") == "perception"
    names = set(tensor_sites_of(tiny_model(), "perception"))
    assert names == {"perception", "perception.backbone", "perception.backbone_0", "perception.backbone_1",
                     "perception.backbone_2", "perception.head"}


@pytest.mark.parametrize("dtype, width", [(torch.float32, 32), (torch.float16, 16), (torch.bfloat16, 16),
                                          (torch.float64, 64)])
@pytest.mark.parametrize("device", DEVICES)
def test_flip_bit_inverts_one_bit_of_one_element(dtype, width, device):
    t = torch.arange(12, dtype=dtype, device=device).reshape(3, 4) / 7 + 0.5
    ref = t.clone()
    for bit in (0, width // 2, width - 1):
        before, after = flip_bit_(t, 6, bit)
        assert before == float(ref.reshape(-1)[6])
        itype = {16: torch.int16, 32: torch.int32, 64: torch.int64}[width]
        diff = (t.view(itype) ^ ref.view(itype)).reshape(-1).cpu()
        assert int((diff != 0).sum()) == 1 and diff[6] != 0
        flip_bit_(t, 6, bit)
        assert torch.equal(t.view(itype), ref.view(itype))


def test_flip_bit_on_a_non_contiguous_view_edits_the_right_element():
    base = torch.zeros(3, 4)
    view = base.t()  # 4x3, not contiguous
    flip_bit_(view, 5, 31)  # row 1, column 2 of the view = base[2, 1]; sign bit of 0.0 → -0.0
    assert struct.pack("<f", float(base[2, 1])) == struct.pack("<f", -0.0)
    assert int((base.view(torch.int32) != 0).sum()) == 1


@pytest.mark.parametrize("dtype", [torch.float32, torch.float16, torch.float64])
def test_flip_bit_contiguous_cpu_path_equals_the_strided_one(dtype):
    # Contiguous CPU tensors flip through a numpy view, others through torch indexing:
    # the same element, bits and reported values (NaN and inf included) either way.
    rng = np.random.default_rng(3)
    width = torch.finfo(dtype).bits
    data = torch.from_numpy(rng.normal(size=(2, 5, 7)) * 1e3).to(dtype)
    data.view(-1)[:3] = torch.tensor([float("nan"), float("inf"), 0.0], dtype=dtype)
    fast = data.clone()
    slow = data.clone().transpose(0, 2).contiguous().transpose(0, 2)  # same values, not contiguous
    assert fast.is_contiguous() and not slow.is_contiguous()
    for k, bit in zip(rng.integers(fast.numel(), size=60).tolist() + [0, 1, 2], rng.integers(width, size=63).tolist()):
        got, want = flip_bit_(fast, k, bit), flip_bit_(slow, k, bit)
        assert np.array_equal(np.array(got), np.array(want), equal_nan=True)
    itype = {16: torch.int16, 32: torch.int32, 64: torch.int64}[width]
    assert torch.equal(fast.view(itype), slow.contiguous().view(itype))
    with pytest.raises(ValueError):
        flip_bit_(fast, fast.numel(), 0)


def test_flip_bit_rejects_integer_tensors():
    with pytest.raises(TypeError):
        flip_bit_(torch.zeros(3, dtype=torch.int32), 0, 1)


def test_ieee_fields_per_dtype():
    assert bit_range(torch.float32, "exponent") == (23, 31)
    assert bit_range(torch.float16, "exponent") == (10, 15)
    assert bit_range(torch.bfloat16, "exponent") == (7, 15)
    assert bit_range(torch.float64, "mantissa") == (0, 52)
    assert bit_range(torch.float32, "sign") == (31, 32)


@pytest.mark.parametrize("device", DEVICES)
def test_weight_flips_persist_and_close_restores_the_model_bit_for_bit(device):
    model, clock = tiny_model(device), Clock()
    clean_state = {k: v.clone() for k, v in model.state_dict().items()}
    x = _x(device)
    with torch.no_grad():
        clean = model(x)
    sched, kind, events = _bind(model, "perception.backbone_0", clock, tensor="weights", count=3, field="exponent",
                                start=1.0, end=1.0)
    with torch.no_grad():
        assert torch.equal(model(x), clean)  # before the instant
        clock.t = 1.0
        faulty = model(x)
        clock.t = 2.0
        again = model(x)
    assert len(events) == 3
    assert all(e.detail["before"] != e.detail["value"] for e in events)
    torch.testing.assert_close(again, faulty, rtol=0, atol=0, equal_nan=True)  # the flips stay
    for e in events:
        d = e.detail
        assert d["location"].startswith("perception.backbone_0:") and d["tensor"] == "weights"
        assert 23 <= d["bit"] < 31 and d["device"].startswith(device) and d["dtype"] == "float32"
    changed = [k for k, v in model.state_dict().items() if not torch.equal(v, clean_state[k])]
    assert changed and all(k.startswith("backbone.0.") for k in changed)
    sched.close()
    for k, v in model.state_dict().items():
        assert torch.equal(v.view(torch.int32), clean_state[k].view(torch.int32)), k
    with torch.no_grad():
        assert torch.equal(model(x), clean)  # hooks are gone too


@pytest.mark.parametrize("device", DEVICES)
def test_activation_flips_affect_one_inference_only(device):
    model, clock = tiny_model(device), Clock()
    x = _x(device)
    with torch.no_grad():
        clean = model(x)
    sched, kind, events = _bind(model, "perception.backbone", clock, tensor="activations", count=2, bit=30,
                                start=0.5, end=0.5)
    with torch.no_grad():
        clock.t = 0.5
        faulty = model(x)
        clock.t = 0.6
        after = model(x)
    assert len(events) == 2 and all(e.detail["bit"] == 30 for e in events)
    assert all(e.detail["location"].startswith("perception.backbone:output[") for e in events)
    assert not torch.equal(faulty, clean)
    assert torch.equal(after, clean)
    assert all(torch.equal(p, q) for p, q in zip(model.parameters(), tiny_model(device).parameters()))
    sched.close()


def test_same_seed_same_tensor_faults():
    def run(seed):
        model, clock = tiny_model(), Clock()
        sched, kind, events = _bind(model, "perception", clock, tensor="weights", count=5, start=0.0, end=3.0,
                                    seed=seed)
        with torch.no_grad():
            for t in np.arange(0, 3.01, 0.1):
                clock.t = float(t)
                model(_x())
        sched.close()
        return [(round(e.time_s, 6), e.detail["location"], e.detail["bit"]) for e in events]

    assert run(3) == run(3)
    assert run(3) != run(4)
    assert len(run(3)) == 5


def test_flips_spread_over_all_parameters_of_the_layer():
    model, clock = tiny_model(), Clock()
    sched, kind, events = _bind(model, "perception", clock, tensor="weights", count=400, bit=0, start=0.0,
                                end=0.0)
    with torch.no_grad():
        model(_x())
    params = {e.detail["location"].split(":")[1].split("[")[0] for e in events}
    # backbone.0.weight has 96 of the 275 elements; every parameter tensor is hit.
    assert params == {n for n, _ in model.named_parameters()}
    sched.close()


def test_a_tensor_site_with_nothing_to_flip_is_an_error():
    model, clock = tiny_model(), Clock()
    with pytest.raises(ValueError, match="no floating-point weights"):
        _bind(model, "perception.backbone_1", clock, tensor="weights")  # ReLU has no parameters
