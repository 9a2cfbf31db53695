"""Shared pieces for agent tests: a small real checker and a domain context."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from agent.prompt import DomainContext

CONTEXT = DomainContext(
    domain="toy",
    task="Stack the blocks.",
    cameras="front: 64x48",
    meshes="block: 4 cm cube, origin at its centre",
    toolbox_docs="(toolbox docs)",
)

# What each function must return for the toy check: an `ok` key set to True.
_PROBE = """
import json, sys, importlib.util
spec = importlib.util.spec_from_file_location("draft", sys.argv[1])
m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m)
out = getattr(m, sys.argv[2])()
print(json.dumps(out))
"""


class ToyChecker:
    """Runs the draft in a subprocess and checks it returns {"ok": True}: a real, tiny check."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, str]] = []

    def check(self, domain, function, source, *, deps, out_dir: Path, cases_seed=None) -> dict:
        self.calls.append((function, source))
        out_dir.mkdir(parents=True, exist_ok=True)
        draft = out_dir / "draft.py"
        draft.write_text(source)
        proc = subprocess.run(
            [sys.executable, "-c", _PROBE, str(draft), function],
            capture_output=True,
            text=True,
            timeout=60,
        )
        ok = proc.returncode == 0 and json.loads(proc.stdout or "null") == {"ok": True}
        check = {
            "name": "returns_ok",
            "category": "property",
            "status": "passed" if ok else "failed",
        }
        if not ok:
            check["expected"] = {"ok": True}
            check["actual"] = proc.stdout.strip() or proc.stderr.strip()[-300:]
        return {
            "schema_version": 1,
            "domain": domain,
            "function": function,
            "passed": ok,
            "first_failure": None if ok else "returns_ok",
            "checks": [check],
        }

    def markdown(self, report: dict) -> str:
        c = report["checks"][0]
        return f"{c['name']}: {c['status']} (expected {c.get('expected')}, got {c.get('actual')})"


def good(function: str) -> str:
    return f"Here it is.\n\n```python\ndef {function}():\n    return {{'ok': True}}\n```\n"


def bad(function: str) -> str:
    return f"```python\ndef {function}():\n    return {{'ok': False}}\n```\n"


@pytest.fixture
def checker() -> ToyChecker:
    return ToyChecker()
