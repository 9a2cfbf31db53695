"""The sandbox wire format: length-prefixed frames and the JSON + `.npz` value codec.

Design rule: whoever reads a frame or a value trusts nothing in it. Frames carry a small JSON
header and raw byte sections, each under a cap that is checked before anything is allocated;
values are JSON with every numpy array replaced by ``{"__ndarray__": "a<i>"}`` and the arrays
in an uncompressed `.npz` read with ``allow_pickle=False`` and a dtype allow-list. Nothing here
imports, unpickles or evaluates anything it received.

This module runs on both sides (host and container), so it imports only the standard library
and numpy, and nothing from the rest of `sandbox`.
"""

from __future__ import annotations

import io
import json
import re
import struct
import zipfile
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

MAGIC = b"RVT1"
_PREFIX = struct.Struct(">4sII")  # magic, header length, number of sections
_SECTION = struct.Struct(">Q")
MAX_HEADER = 1 << 20  # [bytes]
MAX_SECTIONS = 8
ARRAY_KEY = "__ndarray__"
CONST_KEY = "__const__"  # in call arguments only: a constant the program was loaded with
ARRAY_KINDS = frozenset("biufc")  # bool, int, uint, float, complex: nothing that can hold objects
MAX_DEPTH = 64
MAX_ELEMENTS = 1_000_000  # JSON values (numbers, strings, lists, dicts) in one decoded value
MAX_ARRAY_ELEMENTS = 1 << 28  # elements of one array, zero-length dimensions counted as 1
MAX_NDIM = 8
_ARRAY_NAME = re.compile(r"a[0-9]{1,7}")
_SURROGATE = re.compile("[\ud800-\udfff]")
# C0/C1 controls and DEL, but tab and newline: an escape sequence starts with ESC or CSI.
_CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f]")


def clean_text(text: str) -> str:
    """`text` safe for a terminal, a journal, HTML-escaping or a model: lone surrogates become
    U+FFFD and control characters (escape sequences included) become visible ``\\xNN``."""
    if not isinstance(text, str):
        text = str(text)
    text = _SURROGATE.sub("\ufffd", text)
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", text)


class FrameError(Exception):
    """A frame is malformed or over its cap."""


class BadValue(Exception):
    """A value cannot be encoded or decoded; `path` names the offending place (``$`` = root)."""

    def __init__(self, path: str, problem: str) -> None:
        self.path = path
        self.problem = problem
        super().__init__(f"{path}: {problem}")


# --------------------------------------------------------------------------------------------
# Frames


def pack_frame(header: Mapping[str, Any], sections: tuple[bytes, ...] | list[bytes] = ()) -> bytes:
    """One frame: magic, sizes, the header as JSON, then the sections."""
    head = json.dumps(header, separators=(",", ":")).encode()
    if len(head) > MAX_HEADER:
        raise FrameError(f"header of {len(head)} bytes is over the {MAX_HEADER}-byte cap")
    if len(sections) > MAX_SECTIONS:
        raise FrameError(f"{len(sections)} sections is over the cap of {MAX_SECTIONS}")
    parts = [_PREFIX.pack(MAGIC, len(head), len(sections))]
    parts += [_SECTION.pack(len(s)) for s in sections]
    parts.append(head)
    parts += [bytes(s) for s in sections]
    return b"".join(parts)


class FrameReader:
    """Incremental frame parser: `feed` bytes, then take complete frames from `frames()`.

    Args:
        max_bytes: cap on one frame's total size [bytes]; a frame announcing more raises
            `FrameError` before its body arrives.
    """

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes = max_bytes
        self._buf = bytearray()

    @property
    def pending(self) -> int:
        """Bytes received that are not yet part of a complete frame."""
        return len(self._buf)

    def feed(self, data: bytes) -> None:
        self._buf += data
        self._check_sizes()

    def _check_sizes(self) -> tuple[int, list[int]] | None:
        if len(self._buf) < _PREFIX.size:
            return None
        magic, head_len, n = _PREFIX.unpack_from(self._buf)
        if magic != MAGIC:
            raise FrameError(f"bad frame magic {bytes(magic)!r}")
        if head_len > MAX_HEADER or n > MAX_SECTIONS:
            raise FrameError(f"frame announces a {head_len}-byte header and {n} sections")
        fixed = _PREFIX.size + n * _SECTION.size
        if len(self._buf) < fixed:
            return None
        sizes = [
            _SECTION.unpack_from(self._buf, _PREFIX.size + i * _SECTION.size)[0] for i in range(n)
        ]
        total = fixed + head_len + sum(sizes)
        if total > self.max_bytes:
            raise FrameError(f"frame of {total} bytes is over the {self.max_bytes}-byte cap")
        return head_len, sizes

    def frames(self) -> Iterator[tuple[dict[str, Any], list[bytes]]]:
        """Complete frames received so far, in order."""
        while True:
            got = self._check_sizes()
            if got is None:
                return
            head_len, sizes = got
            start = _PREFIX.size + len(sizes) * _SECTION.size
            end = start + head_len + sum(sizes)
            if len(self._buf) < end:
                return
            frame = bytes(self._buf[:end])
            del self._buf[:end]
            try:
                header = json.loads(frame[start : start + head_len])
            except (ValueError, RecursionError) as e:
                raise FrameError(f"frame header is not JSON: {e}") from None
            if not isinstance(header, dict):
                raise FrameError("frame header is not a JSON object")
            sections, pos = [], start + head_len
            for size in sizes:
                sections.append(frame[pos : pos + size])
                pos += size
            yield header, sections


# --------------------------------------------------------------------------------------------
# Values


def encode_value(value: Any, *, max_bytes: int) -> tuple[bytes, bytes]:
    """Encode a value as (JSON bytes, .npz bytes); raises `BadValue` naming the path."""
    text, arrays = encode_tree(value, max_bytes=max_bytes)
    blob = b""
    if arrays:
        buf = io.BytesIO()
        write_npz(buf, arrays)
        blob = buf.getvalue()
    return text, blob


def write_npz(f: Any, arrays: Mapping[str, np.ndarray]) -> None:
    """The .npz section of `encode_tree`'s arrays, written to a binary file (straight to a
    file it skips a growing in-memory copy: a 6 MB observation costs a third of the time)."""
    np.savez(f, **arrays)  # type: ignore[arg-type]


def encode_tree(value: Any, *, max_bytes: int) -> tuple[bytes, dict[str, np.ndarray]]:
    """(JSON bytes, the arrays its ``{"__ndarray__": name}`` markers name); `BadValue`."""
    arrays: dict[str, np.ndarray] = {}
    budget = [max_bytes]

    def spend(n: int, path: str) -> None:
        budget[0] -= n
        if budget[0] < 0:
            raise BadValue(path, f"value is over the {max_bytes}-byte output cap")

    def walk(v: Any, path: str, depth: int, active: set[int]) -> Any:
        if depth > MAX_DEPTH:
            raise BadValue(path, f"nested deeper than {MAX_DEPTH} levels")
        if v is None or isinstance(v, (bool, np.bool_)):
            return None if v is None else bool(v)
        if isinstance(v, (int, np.integer)):
            spend(24, path)
            return int(v)
        if isinstance(v, (float, np.floating)):
            spend(24, path)
            return float(v)
        if isinstance(v, str):
            spend(len(v) + 2, path)
            return str(v)
        if isinstance(v, np.ndarray):
            if v.dtype.kind not in ARRAY_KINDS or v.dtype.fields is not None:
                raise BadValue(path, f"array dtype {v.dtype} is not allowed (bool/int/float only)")
            spend(v.nbytes + 256, path)
            name = f"a{len(arrays)}"
            arrays[name] = np.ascontiguousarray(v)
            return {ARRAY_KEY: name}
        if id(v) in active:
            raise BadValue(path, "value contains a reference cycle")
        if isinstance(v, Mapping):
            out = {}
            active.add(id(v))
            for k, item in v.items():
                if not isinstance(k, str):
                    raise BadValue(path, f"dict key {k!r} is not a str")
                if k == ARRAY_KEY:
                    raise BadValue(path, f"dict key {ARRAY_KEY!r} is reserved")
                spend(len(k) + 4, path)
                out[str(k)] = walk(item, f"{path}.{k}", depth + 1, active)
            active.discard(id(v))
            return out
        if isinstance(v, (list, tuple)):
            active.add(id(v))
            out_list = [walk(item, f"{path}[{i}]", depth + 1, active) for i, item in enumerate(v)]
            active.discard(id(v))
            return out_list
        kind = type(v)
        raise BadValue(path, f"{kind.__module__}.{kind.__qualname__} is not JSON or a numpy array")

    tree = walk(value, "$", 0, set())
    try:
        text = json.dumps(tree, separators=(",", ":")).encode()
    except ValueError as e:  # e.g. an int too long to print
        raise BadValue("$", f"not JSON: {e}") from None
    if len(text) > max_bytes:
        raise BadValue("$", f"value is over the {max_bytes}-byte output cap")
    return text, arrays


def decode_value(text: bytes, blob: bytes, *, max_bytes: int) -> Any:
    """Decode and validate what `encode_value` produced; raises `BadValue`.

    Bounded before anything large is built: the bytes, the number of JSON values (counted on
    the raw text), the nesting depth, every array's shape against its bytes. Strings come out
    with lone surrogates replaced (they cannot be printed or encoded).
    """
    if len(text) + len(blob) > max_bytes:
        raise BadValue("$", f"value of {len(text) + len(blob)} bytes is over the cap")
    # Every JSON value but the first is preceded by '[', '{', ',' or ':' (a key's value);
    # keys are counted too, so this bounds what json.loads would build.
    tokens = text.count(b"[") + text.count(b"{") + text.count(b",") + text.count(b":")
    if tokens > 2 * MAX_ELEMENTS:
        raise BadValue("$", f"value holds more than {MAX_ELEMENTS} JSON elements")
    try:
        tree = json.loads(text)
    except (ValueError, RecursionError) as e:
        raise BadValue("$", f"not valid JSON ({str(e)[:200]})") from None
    arrays = _load_npz(blob, max_bytes=max_bytes) if blob else {}
    used: set[str] = set()

    def walk(v: Any, path: str, depth: int) -> Any:
        if depth > MAX_DEPTH:
            raise BadValue(path, f"nested deeper than {MAX_DEPTH} levels")
        if isinstance(v, dict):
            if ARRAY_KEY in v:
                name = v[ARRAY_KEY]
                if len(v) != 1 or not isinstance(name, str) or name not in arrays:
                    raise BadValue(path, "dangling or malformed array reference")
                used.add(name)
                return arrays[name]
            return {
                _clean_key(k): walk(item, f"{path}.{_clean_key(k)[:40]}", depth + 1)
                for k, item in v.items()
            }
        if isinstance(v, list):
            return [walk(item, f"{path}[{i}]", depth + 1) for i, item in enumerate(v)]
        if isinstance(v, str) and _SURROGATE.search(v):
            return _SURROGATE.sub("\ufffd", v)
        return v

    value = walk(tree, "$", 0)
    if set(arrays) - used:
        raise BadValue("$", f"arrays {sorted(set(arrays) - used)[:5]} are not referenced")
    return value


def _clean_key(k: str) -> str:
    return _SURROGATE.sub("\ufffd", k) if _SURROGATE.search(k) else k


def _load_npz(blob: bytes, *, max_bytes: int) -> dict[str, np.ndarray]:
    """Arrays from an uncompressed .npz, never unpickling, every header checked against the
    member's size before any data is read."""
    try:
        zf = zipfile.ZipFile(io.BytesIO(blob))
    except (zipfile.BadZipFile, ValueError, OSError) as e:
        raise BadValue("$", f"array section is not a .npz archive ({e})") from None
    infos = zf.infolist()
    if len(infos) > MAX_ELEMENTS:
        raise BadValue("$", "too many arrays")
    if sum(i.file_size for i in infos) > max_bytes:
        raise BadValue("$", "arrays are over the output cap once unpacked")
    out: dict[str, np.ndarray] = {}
    for info in infos:
        name = info.filename.removesuffix(".npy")
        if not info.filename.endswith(".npy") or not _ARRAY_NAME.fullmatch(name):
            raise BadValue("$", f"unexpected member {info.filename[:60]!r} in the array section")
        if name in out:
            raise BadValue(f"arrays[{name}]", "the archive holds this array twice")
        if info.compress_type != zipfile.ZIP_STORED:
            raise BadValue(f"arrays[{name}]", "compressed .npz members are not accepted")
        try:
            with zf.open(info) as f:
                shape, dtype = _npy_header(f, info.file_size, name)
                arr = _read_data(f, shape, dtype, name)
        except BadValue:
            raise
        except (ValueError, OSError, EOFError, zipfile.BadZipFile, RuntimeError) as e:
            raise BadValue(f"arrays[{name}]", f"unreadable array ({str(e)[:200]})") from None
        out[name] = arr
    return out


def _npy_header(f: Any, member_size: int, name: str) -> tuple[tuple[int, ...], np.dtype]:
    """(shape, dtype) of a .npy member, refused unless its data fills the member exactly."""
    version = np.lib.format.read_magic(f)
    if version == (1, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(f, max_header_size=10_000)
    elif version in ((2, 0), (3, 0)):
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(f, max_header_size=10_000)
    else:
        raise BadValue(f"arrays[{name}]", f"unknown .npy version {version}")
    if fortran:
        raise BadValue(f"arrays[{name}]", "Fortran-ordered arrays are not accepted")
    if dtype.kind not in ARRAY_KINDS or dtype.fields is not None or dtype.hasobject:
        raise BadValue(f"arrays[{name}]", f"array dtype {dtype} is not allowed (bool/int/float)")
    if len(shape) > MAX_NDIM or any(not isinstance(d, int) or d < 0 for d in shape):
        raise BadValue(f"arrays[{name}]", f"array shape {shape} is not allowed")
    count = 1
    for d in shape:
        count *= max(d, 1)  # an (N, 0) array holds nothing but still costs N when listed
        if count > MAX_ARRAY_ELEMENTS:
            raise BadValue(f"arrays[{name}]", f"array shape {shape} is too large")
    nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if nbytes == 0 and count > MAX_ELEMENTS:  # no bytes pay for it: bounded like JSON values
        raise BadValue(
            f"arrays[{name}]",
            f"empty array of shape {shape} is refused: it holds nothing, but listing it would "
            f"take {count} lists (more than {MAX_ELEMENTS})",
        )
    if f.tell() + nbytes != member_size:
        raise BadValue(
            f"arrays[{name}]",
            f"array header announces {shape} {dtype} ({nbytes} bytes) but the member holds "
            f"{member_size - f.tell()}",
        )
    return tuple(shape), dtype


def _read_data(f: Any, shape: tuple[int, ...], dtype: np.dtype, name: str) -> np.ndarray:
    nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    data = f.read(nbytes)
    if len(data) != nbytes:
        raise BadValue(f"arrays[{name}]", "array data is truncated")
    return np.frombuffer(data, dtype=dtype).reshape(shape).copy()
