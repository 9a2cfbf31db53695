"""`rivet validate` end to end, as a user runs it (a subprocess of the installed console script)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

RIVET = [str(Path(sys.executable).parent / "rivet")]
POSE = [[1, 0, 0, 0.5], [0, 1, 0, 0], [0, 0, 1, 0.02], [0, 0, 0, 1]]


def rivet(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*RIVET, *args], capture_output=True, text=True, timeout=120)


def write(tmp_path: Path, value: object, name: str = "x.json") -> Path:
    path = tmp_path / name
    path.write_text(value if isinstance(value, str) else json.dumps(value))
    return path


def test_valid_scene_exits_0(tmp_path):
    scene = {"domain": "cubes", "objects": [{"id": "red", "mesh": "cube", "pose": POSE}]}
    out = rivet("validate", "scene", str(write(tmp_path, scene)))
    assert out.returncode == 0, out.stderr
    assert "valid scene" in out.stdout


def test_improper_rotation_exits_2_naming_the_path(tmp_path):
    bad = [row[:] for row in POSE]
    bad[2][2] = -1
    scene = {
        "domain": "cubes",
        "objects": [
            {"id": "red", "mesh": "cube", "pose": POSE},
            {"id": "b", "mesh": "cube", "pose": bad},
        ],
    }
    out = rivet("validate", "scene", str(write(tmp_path, scene)))
    assert out.returncode == 2
    assert "objects[1].pose: rotation is not proper (det = -1.000)" in out.stderr


@pytest.mark.parametrize(
    ("content", "fragment"),
    [("{not json", "not JSON: Expecting property name"), (None, "cannot read")],
)
def test_unreadable_files_exit_2(tmp_path, content, fragment):
    path = tmp_path / "missing.json" if content is None else write(tmp_path, content)
    out = rivet("validate", "plan", str(path))
    assert out.returncode == 2
    assert fragment in out.stderr


def test_unknown_kind_is_a_usage_error(tmp_path):
    out = rivet("validate", "scenes", str(write(tmp_path, {})))
    assert out.returncode == 2
    assert "invalid choice: 'scenes'" in out.stderr


def test_every_command_parses_its_documented_options():
    """The options README and DESIGN.md promise are accepted by the parser."""
    from rivet.cli import build_parser

    parser = build_parser()
    cases = [
        [
            "author",
            "cubes",
            "--model",
            "claude-opus-5",
            "--resume",
            "--max-usd",
            "5",
            "--max-calls",
            "9",
            "--attempts",
            "3",
            "--runs",
            "2",
            "--ray",
            "local",
            "--strict",
        ],
        ["author", "cubes", "--replay", "x"],
        ["solve", "cubes", "a", "b"],
        [
            "eval",
            "cubes",
            "--trials",
            "3",
            "--view",
            "view1",
            "--policy",
            "programs",
            "d",
            "--workers",
            "2",
            "--json",
            "o.json",
            "--ray",
            "local",
            "--record",
            "r",
            "--seed",
            "4",
        ],
        ["eval", "--all", "--policy", "oracle"],
        ["check", "cubes", "plan", "f.py"],
        ["diff", "cubes", "HEAD~1"],
        ["scene", "render", "i.json", "--out", "d"],
        ["sandbox", "run", "f.py", "--function", "g"],
        ["validate", "plan", "p.json"],
        ["transcript", "pack", "cubes", "d"],
        ["toolbox", "docs"],
    ]
    for argv in cases:
        args = parser.parse_args(argv)
        assert callable(args.handler), argv
