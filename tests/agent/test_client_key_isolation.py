"""The API key never reaches a draft: with `--sandbox local`, a draft cannot read the rivet
process's environment through /proc (the process is non-dumpable, the harness has no
CAP_SYS_PTRACE), and the protection is what makes the difference (the same job reads the key
when it is switched off)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
FAKE_KEY = "sk-ant-test-FAKE-KEY-0123456789"

# A draft that climbs from its harness to the harness's parent (the rivet process) and reads
# that process's environment.
DRAFT = textwrap.dedent(
    """
    import os

    def f():
        def parent(pid):
            with open(f"/proc/{pid}/stat") as fh:
                return int(fh.read().rsplit(")", 1)[1].split()[1])

        def harness(pid):  # the harness and the template it forks sessions from
            with open(f"/proc/{pid}/cmdline", "rb") as fh:
                return b"sandbox.harness" in fh.read()

        target = os.getppid()
        while harness(target):
            target = parent(target)
        out = {"target": target}
        for name in ("environ", "mem"):
            try:
                with open(f"/proc/{target}/{name}", "rb") as fh:
                    data = fh.read(1 << 20) if name == "environ" else b""
                out[name] = data.decode(errors="replace")
            except OSError as e:
                out[name] = None
                out[name + "_error"] = type(e).__name__
        return out
    """
)

RIVET = textwrap.dedent(
    """
    import json, os, sys
    import sandbox.local_backend as lb
    from sandbox import Job

    if sys.argv[1] == "off":  # the control: no protection
        lb.hide_own_environment = lambda: False
        lb._drop_ptrace = lambda: None
    source = open(sys.argv[2]).read()
    with lb.LocalExecutor(preload="none", quiet=True) as ex:
        report = ex.run(Job(source=source, function="f", timeout_s=30))
    print(json.dumps({"pid": os.getpid(), "verdict": report.verdict, "output": report.output,
                      "detail": report.detail}))
    """
)


def _run(tmp_path: Path, mode: str) -> dict:
    draft = tmp_path / "draft.py"
    draft.write_text(DRAFT)
    proc = subprocess.run(
        [sys.executable, "-c", RIVET, mode, str(draft)],
        env={
            "PATH": "/usr/bin:/bin",
            "PYTHONPATH": str(REPO),
            "ANTHROPIC_API_KEY": FAKE_KEY,
            "RIVET_FORBID_MODEL_API": "1",
        },
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and prctl are Linux's")
def test_a_local_draft_cannot_read_the_rivet_process_environment(tmp_path):
    got = _run(tmp_path, "on")
    assert got["verdict"] == "ok", got
    out = got["output"]
    assert out["target"] == got["pid"]  # it did find the rivet process
    assert out["environ"] is None and out["environ_error"] == "PermissionError", out
    assert out["mem"] is None and out["mem_error"] == "PermissionError", out
    assert FAKE_KEY not in json.dumps(got)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and prctl are Linux's")
def test_without_the_protection_the_same_draft_reads_the_key(tmp_path):
    got = _run(tmp_path, "off")
    assert got["verdict"] == "ok", got
    assert got["output"]["target"] == got["pid"]
    assert FAKE_KEY in (got["output"]["environ"] or "")
