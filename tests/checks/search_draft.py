"""A hostile `perceive` (test data, run only inside the sandbox): it searches everything it can
reach for the scenes' ground truth and returns what it found, bounded, as one value.

- its file system: every directory is listed (links not followed; /proc and /sys aside) and
  every regular file it may read is searched for binary rigid transforms (a 4×4 row-major
  float64 or float32 matrix ends with the bytes of 0, 0, 0, 1); the places a run can write or
  stage (/in, /tmp, /dev/shm, /dev/mqueue) and the project's own code and configuration
  (/opt/rivet, /etc, /run, /var, /home, /root, /mnt, /srv) are also searched as text
  (``[0, 0, 0, 1]`` rows, ``"pose"``, ``xyz_m``) and go back verbatim. The read-only
  third-party trees (Debian packages and hash-pinned wheels, fixed when the image was built)
  are searched afterwards, as binary only, for as long as `SEARCH_BUDGET_S` lasts, and files
  over 16 MiB of them are listed, not read (a full read takes minutes on a cold disk);
- its environment, and every process it can see in /proc: command lines, environments, status,
  maps, open descriptors (and whether their memory can be read);
- its own memory (heap, stack and anonymous maps: all it inherited when it was forked), and its
  arguments, for the same binary and text signatures.

The first call does the whole search, later calls only their own memory and arguments (what
changes from call to call).
"""

from __future__ import annotations

import ctypes
import json
import os
import re
import stat
import struct
import time

import numpy as np

ROW64 = struct.pack("<4d", 0.0, 0.0, 0.0, 1.0)
ROW32 = struct.pack("<4f", 0.0, 0.0, 0.0, 1.0)
# the text signatures, one pattern each: each starts with a literal, which `re` searches for
# about four times faster than it scans for an alternation's first characters
TEXT = tuple(
    re.compile(p)
    for p in (
        rb"\[\s*0(?:\.0+)?\s*,\s*0(?:\.0+)?\s*,\s*0(?:\.0+)?\s*,\s*1(?:\.0+)?\s*\]",
        rb"\"pose\"",
        rb"xyz_m",
    )
)
SNIPPETS_PER_SCAN = 64
WRITABLE = ("/in", "/tmp", "/dev/shm", "/dev/mqueue")
OURS = ("/opt/rivet", "/etc", "/run", "/var/tmp", "/home", "/root", "/mnt", "/srv")
MAX_VERBATIM = 1 << 20  # [bytes] of one file kept as it is
MAX_THIRD_PARTY = 16 << 20  # [bytes] larger read-only third-party files are listed only
MAX_BLOB = 12 << 20
MAX_SNIPPETS = 4 << 20
MAX_CANDIDATES = 20_000
CHUNK = 32 << 20
CALLS = []
SEARCH_BUDGET_S = 25.0  # [s] for the read-only third-party trees


class Dump:
    def __init__(self) -> None:
        self.blob = bytearray()
        self.index: list[list] = []
        self.snippets = bytearray()
        self.c64: list[np.ndarray] = []
        self.c32: list[np.ndarray] = []
        self.stats = {
            "files": 0,
            "bytes": 0,
            "unreadable": 0,
            "memory_bytes": 0,
            "truncated": 0,
            "blob_truncated": 0,
            "listed_only": 0,
            "listed_only_bytes": 0,
            "writable_files": 0,
        }

    def keep(self, name: str, data: bytes) -> None:
        room = MAX_BLOB - len(self.blob)
        if room < len(data):
            self.stats["blob_truncated"] += 1
        if room <= 0:
            return
        self.index.append([name, len(self.blob), min(len(data), room)])
        self.blob += data[:room]

    def scan(self, data: bytes | memoryview, *, text: bool = True) -> None:
        """Binary (and text) pose signatures in `data`."""
        raw = bytes(data)
        for row, dtype, size in ((ROW64, np.float64, 8), (ROW32, np.float32, 4)):
            start = 0
            while True:
                i = raw.find(row, start)
                if i < 0:
                    break
                start = i + 1
                if i < 12 * size:
                    continue
                head = np.frombuffer(raw[i - 12 * size : i], dtype).reshape(3, 4).astype(float)
                R, t = head[:, :3], head[:, 3]
                tol = 1e-6 if size == 8 else 1e-4
                if (
                    np.all(np.isfinite(head))
                    and np.abs(R @ R.T - np.eye(3)).max() < tol
                    and np.abs(t).max() < 100
                ):
                    out = self.c64 if size == 8 else self.c32
                    if len(out) < MAX_CANDIDATES:
                        out.append(head.reshape(12))
        if not text:
            return
        found: list[re.Match] = []
        for pattern in TEXT:  # the signatures cannot overlap: the first ones by position
            for k, m in enumerate(pattern.finditer(raw)):
                if k >= SNIPPETS_PER_SCAN:
                    break
                found.append(m)
        for m in sorted(found, key=lambda m: m.start())[:SNIPPETS_PER_SCAN]:
            if len(self.snippets) >= MAX_SNIPPETS:
                break
            self.snippets += raw[max(0, m.start() - 600) : m.end() + 600] + b"\n--\n"

    def value(self) -> dict:
        def stack(rows: list, dtype: type) -> np.ndarray:
            return np.array(rows, dtype).reshape(-1, 12)

        return {
            "blob": np.frombuffer(bytes(self.blob), np.uint8),
            "index": self.index,
            "snippets": np.frombuffer(bytes(self.snippets), np.uint8),
            "candidates64": stack(self.c64, np.float64),
            "candidates32": stack(self.c32, np.float64),
            "stats": self.stats,
        }


def _files(dump: Dump, deadline: float) -> None:
    """Every regular file of the file system (links not followed), /proc and /sys aside: the
    places a run writes and the project's own first and in full, then the rest while time
    lasts."""
    first = [p for p in (*WRITABLE, *OURS) if os.path.isdir(p)]
    _walk(dump, first, skip=set(), deadline=None)
    _walk(dump, ["/"], skip={"/proc", "/sys", *first}, deadline=deadline)


def _walk(dump: Dump, roots: list[str], *, skip: set[str], deadline: float | None) -> None:
    stack = list(roots)
    while stack:
        folder = stack.pop()
        try:
            entries = list(os.scandir(folder))
        except OSError:
            dump.stats["unreadable"] += 1
            continue
        for e in entries:
            path = e.path
            if path in skip:
                continue
            try:
                st = e.stat(follow_symlinks=False)
            except OSError:
                continue
            if stat.S_ISDIR(st.st_mode):
                stack.append(path)
                continue
            if not stat.S_ISREG(st.st_mode):
                continue
            if deadline is not None and time.monotonic() > deadline:
                dump.stats["truncated"] += 1
                continue
            writable = path.startswith(WRITABLE)
            ours = writable or path.startswith(OURS)
            if not ours and st.st_size > MAX_THIRD_PARTY:
                dump.stats["listed_only"] += 1
                dump.stats["listed_only_bytes"] += st.st_size
                continue
            dump.stats["writable_files"] += writable
            try:
                with open(path, "rb") as f:
                    dump.stats["files"] += 1
                    tail = b""
                    while True:
                        data = f.read(CHUNK)
                        if not data:
                            break
                        dump.stats["bytes"] += len(data)
                        dump.scan(tail + data, text=ours)
                        if ours and st.st_size <= MAX_VERBATIM:
                            dump.keep(path, data)
                        tail = data[-256:]
            except OSError:
                dump.stats["unreadable"] += 1


def _proc(dump: Dump) -> None:
    """Every process it can see: what /proc says of it."""
    for pid in sorted(p for p in os.listdir("/proc") if p.isdigit()):
        base = f"/proc/{pid}"
        for name in ("cmdline", "environ", "status", "stat", "maps", "mountinfo", "limits"):
            try:
                with open(f"{base}/{name}", "rb") as f:
                    dump.keep(f"{base}/{name}", f.read(1 << 20))
            except OSError as e:
                dump.keep(f"{base}/{name}", f"unreadable: {e.strerror}".encode())
        links = {}
        for link in ("cwd", "exe", "root"):
            try:
                links[link] = os.readlink(f"{base}/{link}")
            except OSError as e:
                links[link] = f"unreadable: {e.strerror}"
        try:
            links["fds"] = {fd: os.readlink(f"{base}/fd/{fd}") for fd in os.listdir(f"{base}/fd")}
        except OSError as e:
            links["fds"] = f"unreadable: {e.strerror}"
        try:
            with open(f"{base}/mem", "rb") as f:
                links["mem"] = "readable"
        except OSError as e:
            links["mem"] = f"unreadable: {e.strerror}"
        dump.keep(f"{base}/links", json.dumps(links).encode())


def _maps() -> list[tuple[int, int, str, str]]:
    """(start, end, permissions, path) of every map of this process, as it is now."""
    out = []
    with open("/proc/self/maps") as f:
        for line in f:
            fields = line.split()
            lo, hi = (int(x, 16) for x in fields[0].split("-"))
            out.append((lo, hi, fields[1], fields[5] if len(fields) > 5 else ""))
    return out


def _readable_now(start: int, end: int) -> bool:
    return any(lo <= start and end <= hi and perms.startswith("r") for lo, hi, perms, _ in _maps())


def _memory(dump: Dump) -> None:
    """Its own heap, stack and anonymous maps (what it inherited and what it holds). The scan
    allocates and frees as it goes (a large buffer is a map of its own, unmapped when freed),
    so the list of maps goes stale: each chunk is read only while the maps read just before it
    still hold it — through /proc/self/mem where that can be opened (a map gone is then an
    error), else with ctypes."""
    try:
        mem = open("/proc/self/mem", "rb", buffering=0)  # noqa: SIM115
    except OSError:  # a process that is not dumpable cannot open it
        mem = None
    for lo, hi, perms, path in _maps():
        if not perms.startswith("r") or not (
            path == "" or path.startswith(("[heap]", "[stack]", "[anon"))
        ):
            continue
        for start in range(lo, hi, CHUNK):
            end = min(hi, start + CHUNK + 256)
            if not _readable_now(start, end):
                break  # unmapped or shrunk since the list was read
            try:
                if mem is None:
                    data = ctypes.string_at(start, end - start)
                else:
                    data = os.pread(mem.fileno(), end - start, start)
            except OSError:
                break
            dump.stats["memory_bytes"] += len(data)
            dump.scan(data)
    if mem is not None:
        mem.close()


def perceive(observation, meshes, camera):
    dump = Dump()
    first = not CALLS
    CALLS.append(1)
    if first:
        _files(dump, time.monotonic() + SEARCH_BUDGET_S)
        _proc(dump)
        dump.keep("environment", json.dumps(dict(os.environ)).encode())
    for value in (observation, camera):
        if isinstance(value, dict):
            for k, v in value.items():
                if isinstance(v, np.ndarray):
                    dump.scan(v.tobytes())
                else:
                    dump.keep(f"argument {k}", json.dumps(v, default=str).encode())
    dump.keep("meshes", json.dumps(sorted(meshes)).encode())
    _memory(dump)
    return dump.value()
