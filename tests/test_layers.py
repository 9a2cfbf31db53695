"""The layering is enforced: `make lint` runs import-linter on the contracts in pyproject.toml,
and an import that goes up a layer breaks it."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("rivet", "agent", "experiments", "artifacts", "checks", "sim", "sandbox", "domains", "toolbox",
            "geometry", "contracts")  # fmt: skip
LINT = Path(sys.executable).parent / "lint-imports"


def _copy(tmp_path: Path) -> Path:
    root = tmp_path / "repo"
    root.mkdir()
    shutil.copy(REPO / "pyproject.toml", root)
    for pkg in PACKAGES:
        shutil.copytree(
            REPO / pkg,
            root / pkg,
            ignore=shutil.ignore_patterns("*.json", "*.png", "*.stl", "*.obj"),
        )
    return root


def _lint(root: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(LINT), "--config", str(root / "pyproject.toml"), "--no-cache"],
        cwd=root,
        capture_output=True,
        text=True,
        env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"},
    )


@pytest.fixture(scope="module")
def repo_copy(tmp_path_factory):
    return _copy(tmp_path_factory.mktemp("layers"))


def test_the_layers_hold(repo_copy):
    r = _lint(repo_copy)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "0 broken" in r.stdout


@pytest.mark.parametrize(
    ("module", "line", "edge"),
    [
        ("geometry/_probe.py", "import sim.executor\n", "geometry"),
        ("domains/_probe.py", "from checks import run_checks\n", "domains"),
        ("sandbox/_probe.py", "import toolbox\n", "sandbox"),
        (
            "contracts/_probe.py",
            "def f():\n    import artifacts  # even inside a function\n",
            "contracts",
        ),
    ],
    ids=["geometry->sim", "domains->checks", "sandbox->toolbox", "contracts->artifacts"],
)
def test_an_upward_import_breaks_the_lint(tmp_path, module, line, edge):
    root = _copy(tmp_path)
    (root / module).write_text(line)
    r = _lint(root)
    assert r.returncode != 0, r.stdout
    assert "BROKEN" in r.stdout and edge in r.stdout
