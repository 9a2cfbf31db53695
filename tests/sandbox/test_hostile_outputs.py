"""Hostile outputs (issue 16, part 4): what a job sends back is untrusted data on the host.

Each draft forges its answer frame by hand on the result channel (so nothing of the harness's
own encoder stands between it and the host) — nesting and element bombs within the size cap,
integers too long to parse, .npz members announcing shapes their bytes cannot hold, zero-width
arrays that would list as millions of empty lists, object arrays, headers that do not parse,
exception fields with lone surrogates and terminal escapes — and the host must answer each
with a verdict (never a traceback), without its memory growing by more than a few hundred
MiB (measured with tracemalloc, peak over the job), and with the same harness afterwards.
`rivet sandbox run` is run as a subprocess on the worst of them: its peak RSS stays under
1 GiB and what it prints is strict JSON with no control characters.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import tracemalloc
from pathlib import Path

import pytest

from sandbox import Job

pytestmark = pytest.mark.docker

REPO = Path(__file__).resolve().parents[2]
GIB = 1 << 30

FORGE = r"""
import io, os, time, zipfile
import numpy as np
from sandbox.harness import wire

def _npz(header, data=b""):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
        member = io.BytesIO()
        np.lib.format.write_array_header_1_0(member, header)
        zf.writestr("a0.npy", member.getvalue() + data)
    return b'{"__ndarray__":"a0"}', buf.getvalue()

def _array(shape, descr="<f8", data=b""):
    return _npz({"descr": descr, "fortran_order": False, "shape": shape}, data)

PAYLOADS = {
    "deep_nesting": lambda: (b"[" * 200_000 + b"]" * 200_000, b""),
    "amplified_list": lambda: (b"[" + b"0," * 25_000_000 + b"0]", b""),
    "amplified_dict": lambda: (b"{" + b",".join(b'"%d":0' % i for i in range(2_500_000)) + b"}", b""),
    "amplified_nesting_within_limits": lambda: (
        b"[" + b",".join([b"[" * 60 + b"]" * 60] * 6_000) + b"]", b""),
    "huge_integer": lambda: (b"1" * 20_000_000, b""),
    "shape_bomb_16_tib": lambda: _array((1 << 41, 1)),
    "shape_bomb_2d": lambda: _array((1 << 22, 1 << 22), "|u1"),
    "shape_lies_about_bytes": lambda: _array((1000, 1000), "<f8", b"\0" * 8),
    "zero_width_rows": lambda: _array((1 << 26, 0)),
    "zero_width_deep": lambda: _array((1 << 10, 1 << 10, 1 << 6, 0)),
    "object_array": lambda: _array((3,), "|O", b"\0" * 24),
    "dangling_array": lambda: (b'{"__ndarray__":"a7"}', b""),
}

def f(kind):
    if kind == "unparsable_header":
        head = b'{"status":"returned","x":' + b"[" * 300_000 + b"]" * 300_000 + b"}"
        frame = wire._PREFIX.pack(wire.MAGIC, len(head), 2) + wire._SECTION.pack(2) * 2 + head + b"[]" * 2
    elif kind == "escapes_in_exception":
        frame = wire.pack_frame({"status": "raised", "exception": {
            "type": "Value\ud800Error\x1b[2J", "message": "\x1b]0;owned\x07\udcff\x9b31m",
            "traceback": "\x1b[1;1H" * 1000}})
    else:
        frame = wire.pack_frame({"status": "returned"}, list(PAYLOADS[kind]()))
    view = memoryview(frame)
    while view:
        view = view[os.write(3, view):]
    time.sleep(60)  # never answers on its own: the forged frame is its answer
"""

CASES = {
    "deep_nesting": ("bad_output", ""),
    "amplified_list": ("bad_output", "JSON elements"),
    "amplified_dict": ("bad_output", "JSON elements"),
    "amplified_nesting_within_limits": ("ok", ""),
    "huge_integer": ("bad_output", "not valid JSON"),
    "shape_bomb_16_tib": ("bad_output", "too large"),
    "shape_bomb_2d": ("bad_output", "too large"),
    "shape_lies_about_bytes": ("bad_output", "announces"),
    "zero_width_rows": ("bad_output", "empty array"),
    "zero_width_deep": ("bad_output", "empty array"),
    "object_array": ("bad_output", "not allowed"),
    "dangling_array": ("bad_output", "dangling"),
    "unparsable_header": ("bad_output", "does not carry frames"),
    "escapes_in_exception": ("exception", ""),
}


def _no_controls(text: str) -> bool:
    """No lone surrogate and no control character but tab and newline (ESC, CSI, BEL...)."""
    return not any(
        0xD800 <= ord(c) <= 0xDFFF or (ord(c) < 32 and c not in "\t\n") or 0x7F <= ord(c) <= 0x9F
        for c in text
    )


@pytest.mark.parametrize("kind", list(CASES))
def test_a_forged_hostile_answer_gets_a_verdict_and_bounded_host_memory(docker_executor, kind):
    want, detail = CASES[kind]
    restarts = docker_executor.restarts
    job = Job(source=FORGE, function="f", inputs={"kind": kind}, timeout_s=60, memory_mb=1024)
    tracemalloc.start()
    try:
        report = docker_executor.run(job)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert report.verdict == want, report
    assert detail in report.detail, report.detail
    assert peak < 400 << 20, f"the host's memory grew by {peak >> 20} MiB decoding it"
    for text in (report.detail, report.stdout_tail, report.stderr_tail):
        assert _no_controls(text), text
    if report.exception is not None:
        assert all(_no_controls(t) for t in vars(report.exception).values()), report.exception
    assert docker_executor.restarts == restarts, "the harness had to be restarted"
    json.dumps(report.to_dict(max_elements=10_000), allow_nan=False)  # always printable


# Linux carries a process's peak RSS across fork and exec, so a child of this (large) pytest
# process would report pytest's own peak: a small launcher starts `rivet` and measures it.
_MEASURE = """
import os, subprocess, sys
proc = subprocess.Popen(sys.argv[2:])
_, status, usage = os.wait4(proc.pid, 0)
with open(sys.argv[1], "w") as f:
    f.write(str(usage.ru_maxrss))
sys.exit(os.waitstatus_to_exitcode(status))
"""


def _rivet(args: list[str], cwd: Path) -> tuple[int, str, str, int]:
    """Run `rivet` as its own process: (exit code, stdout, stderr, peak RSS [bytes])."""
    with (
        tempfile.TemporaryFile() as out,
        tempfile.TemporaryFile() as err,
        tempfile.NamedTemporaryFile("r") as rss,
    ):
        proc = subprocess.run(
            [sys.executable, "-c", _MEASURE, rss.name, sys.executable, "-m", "rivet.cli", *args],
            stdout=out,
            stderr=err,
            cwd=cwd,
            env={**os.environ, "PYTHONPATH": str(REPO)},
            check=False,
        )
        out.seek(0)
        err.seek(0)
        peak_kib = int(rss.read() or 0)
        return proc.returncode, out.read().decode(), err.read().decode(), peak_kib * 1024


def _strict_json(text: str):
    def refuse(name):
        raise ValueError(f"bare {name} in the output")

    return json.loads(text, parse_constant=refuse)


def test_rivet_sandbox_run_on_a_zero_width_bomb_stays_small(tmp_path, sandbox_image):
    draft = tmp_path / "bomb.py"
    draft.write_text(FORGE)
    code, out, err, rss = _rivet(
        ["sandbox", "run", str(draft), "--function", "f", "--input", '{"kind": "zero_width_rows"}'],
        REPO,
    )
    assert code == 1, err[-2000:]
    report = _strict_json(out)
    assert report["verdict"] == "bad_output" and "empty array" in report["detail"], report
    assert rss < GIB, f"rivet sandbox run peaked at {rss >> 20} MiB"
    assert "Traceback" not in err


NASTY = r"""
import numpy as np
def f():
    print("\x1b]0;owned\x07\x1b[2J\x9b printed")
    return {"nan": float("nan"), "inf": float("-inf"), "array": np.array([np.nan, np.inf, 1.0]),
            "empty": np.zeros((500_000, 0)), "text": "\x1b[31mred\x9b1m\ud800\udfff",
            "\x1b[2Jkey": 1}
def g():
    raise ValueError("\x1b]0;owned\x07\x1b[2J\ud800 and contracts.checks and SandboxUnavailable")
"""


@pytest.mark.parametrize("function", ["f", "g"])
def test_rivet_sandbox_run_prints_strict_json_without_escapes(tmp_path, sandbox_image, function):
    draft = tmp_path / "nasty.py"
    draft.write_text(NASTY, encoding="utf-8", errors="surrogatepass")
    code, out, err, rss = _rivet(["sandbox", "run", str(draft), "--function", function], REPO)
    assert "Traceback" not in err, err[-3000:]
    for stream in (out, err):
        assert _no_controls(stream.replace("\r", "")), stream[-2000:]
    report = _strict_json(out)
    assert rss < GIB
    if function == "f":
        assert code == 0 and report["verdict"] == "ok", report
        value = report["output"]
        assert value["nan"] == "NaN" and value["inf"] == "-Infinity", value
        assert value["array"] == ["NaN", "Infinity", 1.0]
        assert value["empty"]["array"]["shape"] == [500_000, 0]  # a summary, not 500,000 lists
        assert "printed" in report["stdout_tail"]
    else:
        assert code == 1 and report["verdict"] == "exception", report
        assert "contracts.checks" in report["exception"]["message"]
