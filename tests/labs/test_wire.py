"""The grader's data-only channel (``avblocks.labs.wire``).

Round trips are checked against the values sent (every dtype the channel
carries, shapes from 0-d to 8-d, hypothesis-drawn arrays); decoded arrays
must be read-only. Every malformed message the student's process could
send (a pickle, garbage, oversized claims, deep nesting, unknown markers,
arrays whose bytes do not match their shape) must be a ``WireError`` with
a message, never another exception and never a large allocation."""

from __future__ import annotations

import io
import json
import math
import pickle
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from avblocks.labs import wire


def roundtrip(value, **kw):
    data = wire.encode(value, **kw)
    return wire.read(io.BytesIO(data).read, **kw)[0], data


def frame(header: bytes, blobs=b"") -> bytes:
    return b"AVL1" + struct.pack(">I", len(header)) + header + blobs


def read(data, **kw):
    buf = io.BytesIO(data)

    def exact(n):
        b = buf.read(n)
        if len(b) < n:
            raise EOFError
        return b
    return wire.read(exact, **kw)[0]


def test_values_come_back_equal_with_their_types():
    value = {"t": 0.25, "big": 2 ** 62, "neg": -3, "yes": True, "none": None,
             "s": "caf\u00e9 \u2192", "tuple": (1, 2.5, "x"), "list": [[], [1, [2, [3]]]],
             "inf": math.inf, "ninf": -math.inf, "empty": {}}
    back, _ = roundtrip(value)
    nan_back, _ = roundtrip(math.nan)
    assert back == value and type(back["tuple"]) is tuple and math.isnan(nan_back)


@pytest.mark.parametrize("dtype", sorted(wire.DTYPES))
@pytest.mark.parametrize("shape", [(), (0,), (3,), (0, 2), (4, 3), (2, 1, 3, 1, 2, 1, 1, 2)])
def test_every_dtype_and_shape_round_trips_read_only(dtype, shape):
    rng = np.random.default_rng(len(shape))
    a = (rng.normal(size=shape) * 50).astype(np.dtype(dtype)) if np.dtype(dtype).kind != "b" \
        else rng.random(shape) > 0.5
    back, _ = roundtrip({"a": a})
    b = back["a"]
    assert b.dtype == a.dtype and b.shape == a.shape
    np.testing.assert_array_equal(b, a)
    assert not b.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        b[...] = 0


def test_numpy_scalars_keep_their_dtype_and_big_endian_becomes_little():
    back, _ = roundtrip([np.float32(1.5), np.int16(-7), np.bool_(True),
                         np.arange(4, dtype=">f8")])
    assert [x.dtype.str for x in back] == ["<f4", "<i2", "|b1", "<f8"]
    assert back[0] == 1.5 and back[1] == -7 and back[2]
    np.testing.assert_array_equal(back[3], np.arange(4.0))


@settings(max_examples=60, deadline=None)
@given(hnp.arrays(dtype=st.sampled_from(["<f8", "<f4", "<i8", "|u1", "|b1", "<c16"]),
                  shape=hnp.array_shapes(min_dims=0, max_dims=4, max_side=5)))
def test_any_array_round_trips(a):
    back, _ = roundtrip(a)
    assert back.dtype == a.dtype and back.shape == a.shape
    np.testing.assert_array_equal(back, a)


def test_what_is_not_data_arrives_as_its_name_only():
    class Secret:
        def __reduce__(self):
            raise AssertionError("never pickled")
    back, data = roundtrip([print, Secret(), np.array([object()]), np.array(["a"]),
                            np.zeros(2, dtype=[("x", "f8")]), {1: 2}, b"bytes", 2 ** 70])
    assert [type(x) for x in back] == [wire.NotData] * 8
    assert back[0].what == "a builtin_function_or_method object"
    assert back[1].what == "a Secret object" and back[5].what.startswith("a dict whose keys")
    assert b"pickle" not in data and b"__reduce__" not in data


def test_the_array_namespace_crosses_only_when_allowed():
    data = wire.encode([np, 1], allow_xp=True)
    assert read(data, allow_xp=True) == [np, 1]
    with pytest.raises(wire.WireError, match="unknown or misused marker '\\$x'"):
        read(data)


def test_encoding_refuses_what_breaks_the_limits():
    small = wire.Limits(message_bytes=1000, depth=3, values=50)
    with pytest.raises(wire.WireError, match="arrays of 8000 bytes, over the limit of 1000"):
        wire.encode(np.zeros(1000), small)
    with pytest.raises(wire.WireError, match="nested deeper than 3 levels"):
        wire.encode([[[[[1]]]]], small)
    with pytest.raises(wire.WireError, match="more than 50 values"):
        wire.encode(list(range(100)), small)


@pytest.mark.parametrize("data,says", [
    (pickle.dumps({"passed": True}), "does not start with b'AVL1'"),
    (b"\x00" * 64, "does not start with b'AVL1'"),
    (b"AVL1" + struct.pack(">I", 2 ** 31), "a header of 2147483648 bytes"),
    (frame(b"{not json"), "a header that is not JSON"),
    (frame(b'{"v": NaN, "b": []}'), "a header that is not JSON"),
    (frame(b'{"v": 1}'), 'a header that is not {"v": value, "b": [blob sizes]}'),
    (frame(b'{"v": 1, "b": [-1]}'), "blob sizes that are not whole numbers"),
    (frame(b'{"v": 1, "b": [10000000000]}'), "over the limit of 16777216 bytes"),
    (frame(b'{"v": {"$eval": "1"}, "b": []}'), "unknown or misused marker '$eval'"),
    (frame(b'{"v": {"$a": [0, "<f8", [3]], "$d": []}, "b": []}'), "not one of the channel"),
    (frame(b'{"v": {"$a": [0, "|O", [1]]}, "b": [8]}', b"\x00" * 8), "dtype '|O'"),
    (frame(b'{"v": {"$a": [0, "<f8", [3]]}, "b": [16]}', b"\x00" * 16), "needs 24 bytes"),
    (frame(b'{"v": {"$a": [1, "<f8", [1]]}, "b": [8]}', b"\x00" * 8), "naming blob 1 of 1"),
    (frame(b'{"v": {"$a": [0, "<f8", [1,1,1,1,1,1,1,1,1]]}, "b": [8]}', b"\x00" * 8),
     "not a few whole numbers"),
    (frame(b'{"v": {"$d": [[1, 2]]}, "b": []}'), "a dict entry that is not [key, value]"),
    (frame(json.dumps({"v": [[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]],
                       "b": []}).encode()), "nested deeper than 32 levels"),
    (frame(b'{"v": ' + b"[" * 100000 + b"]" * 100000 + b', "b": []}'),
     "a header that is not JSON"),
    (frame(b'{"v": ' + b"9" * 5000 + b', "b": []}'), "a header that is not JSON"),
    (frame(b'{"v": "' + b"x" * 300000 + b'", "b": []}'), "a string of 300000 characters"),
])
def test_every_malformed_message_is_a_wire_error(data, says):
    with pytest.raises(wire.WireError) as e:
        read(data)
    assert says in str(e.value), str(e.value)


def test_a_truncated_message_is_the_end_of_the_channel():
    data = wire.encode({"x": np.arange(10.0)})
    with pytest.raises(EOFError):
        read(data[:-3])
