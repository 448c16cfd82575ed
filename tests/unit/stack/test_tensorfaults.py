"""Bit flips in torch tensors: exact values, IEEE-754 fields, transient activation hooks."""

import math
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

torch = pytest.importorskip("torch")
pytestmark = pytest.mark.torch

from addt_dsl.stack.tensorfaults import FLOAT32_FIELDS, ActivationFlip, bit_field, flip_bits  # noqa: E402

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def _f32_bits(x: float) -> int:
    return struct.unpack("<I", struct.pack("<f", x))[0]


@pytest.mark.parametrize("device", DEVICES)
def test_known_bits_of_one(device):
    t = torch.ones(4, device=device)
    before, after = flip_bits(t, [0, 1, 2, 3], [31, 30, 23, 0])
    assert before == [1.0] * 4
    assert after[0] == -1.0  # sign
    assert after[1] == math.inf  # 0x3F800000 ^ 0x40000000 = 0x7F800000
    assert after[2] == 0.5  # lowest exponent bit: 2^0 -> 2^-1
    assert after[3] == 1.0 + 2.0 ** -23  # lowest mantissa bit
    assert t.tolist() == after


@settings(max_examples=60, deadline=None)
@given(st.floats(width=32, allow_nan=False), st.integers(0, 31))
def test_flip_matches_integer_xor_and_is_an_involution(x, bit):
    t = torch.tensor([x], dtype=torch.float32)
    word = t.view(torch.int32).item() & 0xFFFFFFFF
    assert word == _f32_bits(x)
    flip_bits(t, [0], [bit])
    # Compare words, not Python floats: a flip can make a signalling NaN, which a
    # float conversion would quieten.
    assert t.view(torch.int32).item() & 0xFFFFFFFF == word ^ (1 << bit)
    flip_bits(t, [0], [bit])
    assert t.view(torch.int32).item() & 0xFFFFFFFF == word


def test_repeated_index_composes_and_other_elements_are_untouched():
    t = torch.arange(6, dtype=torch.float32).reshape(2, 3)
    flip_bits(t, [4, 4], [31, 31])
    assert t.tolist() == [[0, 1, 2], [3, 4, 5]]
    flip_bits(t, [5], [31])
    assert t.tolist() == [[0, 1, 2], [3, 4, -5]]


def test_bad_arguments_are_rejected():
    t = torch.zeros(3)
    with pytest.raises(IndexError):
        flip_bits(t, [3], [0])
    with pytest.raises(ValueError):
        flip_bits(t, [0], [32])
    with pytest.raises(TypeError):
        flip_bits(torch.zeros(3, dtype=torch.int32), [0], [0])
    with pytest.raises(ValueError):
        bit_field("fraction")


def test_float32_fields_partition_the_word():
    bits = sorted(b for name in ("sign", "exponent", "mantissa") for b in range(*bit_field(name)))
    assert bits == list(range(32))
    assert FLOAT32_FIELDS["any"] == (0, 32)


@pytest.mark.parametrize("device", DEVICES)
def test_activation_flip_is_transient(device):
    torch.manual_seed(0)
    layer = torch.nn.Linear(4, 3).to(device)
    x = torch.ones(1, 4, device=device)
    clean = layer(x).detach().clone()
    with ActivationFlip(layer, [2], [31]) as flip:
        faulty = layer(x).detach().clone()
        again = layer(x).detach().clone()  # still inside the context: already disarmed
    assert faulty[0, 2].item() == -clean[0, 2].item()
    assert torch.equal(faulty[0, :2], clean[0, :2])
    assert torch.equal(again, clean)
    assert flip.fired == ([clean[0, 2].item()], [-clean[0, 2].item()])
    assert torch.equal(layer(x), clean)  # weights untouched
