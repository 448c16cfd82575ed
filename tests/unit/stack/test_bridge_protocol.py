"""The external-stack bridge's wire format and registration (no simulator needed)."""

import socket

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from addt_dsl.registry import STACKS
from addt_dsl.stack.bridge import ExternalStack, decode, encode, parse_address, recv, send

arrays = hnp.arrays(dtype=st.sampled_from([np.float64, np.float32, np.int64, np.int32]),
                    shape=hnp.array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=5))


@settings(max_examples=60, deadline=None)
@given(st.dictionaries(st.text(min_size=1, max_size=8), arrays, max_size=4),
       st.floats(allow_nan=False), st.integers())
def test_encode_decode_round_trips_bit_for_bit(blobs, f, i):
    header = {"type": "step", "time_s": f, "n": i, "nested": {"a": [1, 2.5, "x"]}}
    data = encode(header, blobs)
    got_header, got_blobs = decode(data[4:])
    assert got_header == header
    assert set(got_blobs) == set(blobs)
    for name, arr in blobs.items():
        assert got_blobs[name].dtype == arr.dtype.newbyteorder("<")
        assert got_blobs[name].tobytes() == np.ascontiguousarray(arr).astype(arr.dtype.newbyteorder("<")).tobytes()
        assert got_blobs[name].shape == arr.shape


def test_length_prefix_covers_the_message_and_trailing_bytes_are_an_error():
    data = encode({"type": "bye"})
    assert int.from_bytes(data[:4], "big") == len(data) - 4
    with pytest.raises(ValueError):
        decode(data[4:] + b"\0")


def test_send_recv_over_a_socket_pair():
    a, b = socket.socketpair()
    with a, b:
        pts = np.arange(12, dtype=np.float64).reshape(4, 3)
        send(a, {"type": "frame"}, {"points": pts})
        header, blobs = recv(b)
    assert header == {"type": "frame"} and np.array_equal(blobs["points"], pts)


def test_address_parsing():
    assert parse_address("127.0.0.1:5555") == ("127.0.0.1", 5555)
    assert parse_address(":7000") == ("127.0.0.1", 7000)
    for bad in ("localhost", "host:port", "1.2.3.4:"):
        with pytest.raises(ValueError):
            parse_address(bad)


def test_external_stack_is_registered_with_pass_through_settings():
    assert STACKS.implementation("external") is ExternalStack
    names = {p.name for p in ExternalStack.params}
    assert {"address", "timeout", "sites", "perception", "cruise_speed"} <= names
