"""`rivet solve` as a user runs it, on small frozen programs and observation folders written
from arrays (no simulator): errors by audience, and the thin runtime without MuJoCo.

- a frozen program's invalid plan is the work failing (exit 1), a user's malformed file bad
  input (exit 2), with the contract's message either way;
- `rivet solve` runs — frozen programs in a `--sandbox local` session — with `mujoco`,
  `anthropic` and `docker` impossible to import in the rivet process: none is ever asked for.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from artifacts import build_manifest, freeze
from artifacts.observations import write_observation
from rivet.cli import main

AUTHOR = {"kind": "people", "names": ["RIVET tests"]}
SOURCES = {
    "render": "def render(records, meshes, camera):\n    return {'n': len(records)}\n",
    "perceive": "def perceive(observation, meshes, camera):\n"
    "    x = float(observation['depth'][0][0])\n"
    "    pose = [[1.0, 0, 0, x], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]]\n"
    "    return [{'id': 'red', 'mesh': 'cube', 'pose': pose}]\n",
    "relate": "def relate(records, meshes):\n"
    "    return {'directed': True, 'multigraph': True, 'graph': {}, "
    "'nodes': [{'id': r['id']} for r in records], 'edges': []}\n",
    "plan": "def plan(start, goal, meshes):\n"
    "    g = goal['objects'][0]['pose']\n"
    "    return {'status': 'ok', 'steps': [{'object': 'red', 'target_pose': g}]}\n",
}
GARBAGE_PLAN = (
    "def plan(start, goal, meshes):\n"
    "    return {'status': 'ok', 'steps': [{'object': 'red', 'target_pose': [[1, 0], [0, 1]]}]}\n"
)
CAMERA = {
    "width": 8,
    "height": 6,
    "K": [[10.0, 0.0, 3.5], [0.0, 10.0, 2.5], [0.0, 0.0, 1.0]],
    "T_world_camera": np.eye(4),
}
FORBIDDEN = ("mujoco", "anthropic", "docker")
# Runs the CLI with FORBIDDEN made unimportable; reports every attempt (with its stack) and what
# sys.modules holds at exit.
GUARDED = f"""
import json, sys, traceback
FORBIDDEN = {FORBIDDEN!r}
attempts = []
class Refuse:
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in FORBIDDEN:
            attempts.append(name + "\\n" + "".join(traceback.format_stack(limit=12)))
            raise ModuleNotFoundError(f"No module named {{name!r}} (refused by the test)", name=name)
        return None
early = sorted(m for m in sys.modules if m.partition(".")[0] in FORBIDDEN)
sys.meta_path.insert(0, Refuse())
from rivet.cli import main
rc = main(sys.argv[1:])
loaded = sorted(m for m in sys.modules if m.partition(".")[0] in FORBIDDEN)
print("GUARD " + json.dumps({{"early": early, "loaded": loaded, "attempts": attempts}}), file=sys.stderr)
sys.exit(rc)
"""


def _root(tmp_path: Path, plan_source: str | None = None) -> Path:
    """An artifact root holding a frozen `cubes` set (the toy programs above)."""
    sources = {**SOURCES, "plan": plan_source or SOURCES["plan"]}
    root = tmp_path / "artifacts"
    assert freeze("cubes", sources, build_manifest("cubes", sources, author=AUTHOR), root)
    return root


def _observation(folder: Path, x: float) -> Path:
    obs = {
        "rgb": np.zeros((6, 8, 3), np.uint8),
        "depth": np.full((6, 8), x, np.float32),
        "camera": CAMERA,
    }
    return write_observation(obs, folder)


@pytest.fixture
def folders(tmp_path):
    return str(_observation(tmp_path / "start", 0.4)), str(_observation(tmp_path / "goal", 0.5))


def _argv(root: Path, start: str, goal: str) -> list[str]:
    return ["solve", "cubes", start, goal, "--artifacts", str(root), "--sandbox", "local"]


def test_a_frozen_programs_invalid_plan_exits_1(tmp_path, folders, capsys):
    assert main(_argv(_root(tmp_path, GARBAGE_PLAN), *folders)) == 1
    out = capsys.readouterr()
    assert "the frozen `plan` returned an invalid plan: plan: steps[0].target_pose" in out.err
    assert out.out == ""


def test_a_users_malformed_camera_file_exits_2_with_the_contracts_message(
    tmp_path, folders, capsys
):
    start, goal = folders
    cam = json.loads((Path(goal) / "camera.json").read_text())
    cam["K"][0][0] = -10.0
    (Path(goal) / "camera.json").write_text(json.dumps(cam))
    assert main(_argv(_root(tmp_path), start, goal)) == 2
    message = "observation: K: focal lengths must be positive, got fx=-10.0, fy=10.0"
    assert f"{Path(goal) / 'camera.json'}: {message}" in capsys.readouterr().err


def test_a_users_malformed_instance_file_exits_2(tmp_path, capsys):
    eye = np.eye(4).tolist()
    bad = [row[:] for row in eye]
    bad[2][2] = -1.0  # a reflection
    scene = {"domain": "cubes", "objects": [{"id": "red", "mesh": "cube", "pose": bad}]}
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"domain": "cubes", "start": scene, "goal": scene}))
    message = "start.objects[0].pose: rotation is not proper (det = -1.000)"
    for argv in (
        ["validate", "instance", str(path)],
        ["eval", "cubes", "--instances", str(path)],
    ):
        assert main(argv) == 2, argv
        assert message in capsys.readouterr().err, argv


def test_solve_never_imports_mujoco_the_model_sdk_or_docker(tmp_path, folders):
    argv = _argv(_root(tmp_path), *folders)
    out = subprocess.run(
        [sys.executable, "-c", GUARDED, *argv],
        capture_output=True,
        text=True,
        timeout=120,
        env=os.environ.copy(),
    )
    assert out.returncode == 0, out.stderr
    plan = json.loads(out.stdout)
    assert plan["status"] == "ok" and plan["steps"][0]["target_pose"][0][3] == 0.5
    guard = next(line for line in out.stderr.splitlines() if line.startswith("GUARD "))
    report = json.loads(guard.removeprefix("GUARD "))
    assert report["early"] == [] and report["loaded"] == []
    assert report["attempts"] == [], "\n".join(report["attempts"])
