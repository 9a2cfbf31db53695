"""The wire format: frames under caps, and values that decode without ever unpickling."""

from __future__ import annotations

import io
import os
import struct
import zipfile

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sandbox.harness import wire

LIMIT = 1 << 20


def roundtrip(value):
    text, blob = wire.encode_value(value, max_bytes=LIMIT)
    return wire.decode_value(text, blob, max_bytes=LIMIT)


json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**60), 2**60)
    | st.floats(allow_nan=False)
    | st.text(max_size=20),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=20,
)


@settings(max_examples=60, derandomize=True, deadline=None)
@given(json_values)
def test_json_values_roundtrip(value):
    assert roundtrip(value) == value


def test_arrays_roundtrip_with_dtype_and_shape():
    value = {
        "pose": np.eye(4),
        "mask": np.arange(12, dtype=np.int32).reshape(3, 4),
        "rgb": np.zeros((2, 3, 3), np.uint8),
        "nested": [np.array([True, False]), {"z": np.array([1j], np.complex64)}],
        "scalar": np.float32(2.5),
    }
    out = roundtrip(value)
    assert out["pose"].dtype == np.float64 and np.array_equal(out["pose"], np.eye(4))
    assert out["mask"].dtype == np.int32 and out["mask"].shape == (3, 4)
    assert out["rgb"].shape == (2, 3, 3)
    assert out["nested"][0].dtype == bool
    assert out["nested"][1]["z"][0] == 1j and out["scalar"] == 2.5


def test_tuples_become_lists_and_nan_survives():
    out = roundtrip({"t": (1, 2), "nan": float("nan")})
    assert out["t"] == [1, 2] and np.isnan(out["nan"])


@pytest.mark.parametrize(
    ("value", "problem"),
    [
        (object(), "builtins.object is not JSON"),
        ({1: "a"}, "is not a str"),
        ({"__ndarray__": "a0"}, "reserved"),
        (np.array([object()], dtype=object), "dtype object"),
        (np.zeros(2, dtype=[("a", "f4")]), "dtype"),
        ({1, 2}, "builtins.set"),
        (b"bytes", "builtins.bytes"),
        pytest.param(10**5000, "not JSON", id="huge-int"),
        ("x" * (LIMIT + 1), "output cap"),
        (np.zeros(LIMIT + 1, np.uint8), "output cap"),
    ],
)
def test_unencodable_values_name_the_problem(value, problem):
    with pytest.raises(wire.BadValue, match=problem):
        wire.encode_value({"k": value}, max_bytes=LIMIT)


def test_cycles_and_depth_are_refused():
    cyclic: list = []
    cyclic.append(cyclic)
    with pytest.raises(wire.BadValue, match="cycle"):
        wire.encode_value(cyclic, max_bytes=LIMIT)
    deep: list = []
    for _ in range(100):
        deep = [deep]
    with pytest.raises(wire.BadValue, match="deeper"):
        wire.encode_value(deep, max_bytes=LIMIT)


def _npz(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


class _Payload:
    def __reduce__(self):
        return (os.system, ("touch /tmp/rivet-wire-test-pwned",))


def test_pickled_object_arrays_are_never_loaded():
    blob = _npz(a0=np.array([_Payload()], dtype=object))
    with pytest.raises(wire.BadValue, match="dtype object is not allowed"):
        wire.decode_value(b'{"__ndarray__":"a0"}', blob, max_bytes=LIMIT)
    assert not os.path.exists("/tmp/rivet-wire-test-pwned")


def test_compressed_members_and_zip_bombs_are_refused():
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("a0.npy", b"\0" * (4 * LIMIT))  # 4 MiB that compress to a few KiB
    with pytest.raises(wire.BadValue, match="over the output cap once unpacked"):
        wire.decode_value(b'{"__ndarray__":"a0"}', buf.getvalue(), max_bytes=LIMIT)
    buf = io.BytesIO()
    arr = io.BytesIO()
    np.save(arr, np.zeros(4))
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("a0.npy", arr.getvalue())
    with pytest.raises(wire.BadValue, match="compressed"):
        wire.decode_value(b'{"__ndarray__":"a0"}', buf.getvalue(), max_bytes=LIMIT)


@pytest.mark.parametrize(
    ("text", "blob", "problem"),
    [
        (b'{"__ndarray__":"a1"}', _npz(a0=np.zeros(2)), "dangling"),
        (b'{"__ndarray__":"a0","x":1}', _npz(a0=np.zeros(2)), "malformed"),
        (b"[1]", _npz(a0=np.zeros(2)), "not referenced"),
        (b"{", b"", "not valid JSON"),
        (b'{"__ndarray__":"a0"}', b"not a zip", "not a .npz"),
        (b'{"__ndarray__":"evil"}', _npz(evil=np.zeros(2)), "unexpected member"),
        (b"[" * 10000 + b"]" * 10000, b"", "deeper|not valid JSON"),
    ],
)
def test_bad_payloads_are_refused(text, blob, problem):
    with pytest.raises(wire.BadValue, match=problem):
        wire.decode_value(text, blob, max_bytes=LIMIT)


def test_frames_split_anywhere_reassemble():
    frames = [wire.pack_frame({"n": i}, [b"a" * i, b"b"]) for i in range(5)]
    data = b"".join(frames)
    reader = wire.FrameReader(LIMIT)
    got = []
    for i in range(0, len(data), 7):
        reader.feed(data[i : i + 7])
        got += list(reader.frames())
    assert [h["n"] for h, _ in got] == list(range(5))
    assert got[3][1] == [b"aaa", b"b"] and reader.pending == 0


def test_frames_over_the_cap_are_refused_before_their_body():
    reader = wire.FrameReader(1000)
    with pytest.raises(wire.FrameError, match="over the"):
        reader.feed(struct.pack(">4sII", wire.MAGIC, 2, 1) + struct.pack(">Q", 1 << 40))
    with pytest.raises(wire.FrameError, match="magic"):
        wire.FrameReader(1000).feed(b"GET / HTTP/1.1\r\n")
    reader = wire.FrameReader(1000)
    reader.feed(struct.pack(">4sII", wire.MAGIC, 2, 0) + b"[]")
    with pytest.raises(wire.FrameError, match="not a JSON object"):
        list(reader.frames())
