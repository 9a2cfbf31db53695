"""`rivet solve` end to end: a hand-written instance rendered to folders, then the frozen cubes
programs plan from them; the plan, applied abstractly, reaches the goal."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import domains
from sim.settle import check_order

RIVET = str(Path(sys.executable).parent / "rivet")
REPO = Path(__file__).resolve().parents[2]


def _pose(x, y, z, yaw=0.0):
    c, s = np.cos(yaw), np.sin(yaw)
    return [[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, z], [0, 0, 0, 1]]


@pytest.mark.slow
def test_solve_hand_written_instance(tmp_path):
    ids = ["red", "green", "blue", "yellow", "purple", "cyan"]
    start = [
        {
            "id": i,
            "mesh": "cube",
            "pose": _pose(0.40 + 0.09 * (k % 3), -0.15 + 0.15 * (k // 3), 0.02, 0.3 * k),
        }
        for k, i in enumerate(ids)
    ]
    # goal: a three-cube tower of red/green/blue; the others stay where they are
    goal = [dict(o) for o in start]
    for level, i in enumerate(["red", "green", "blue"]):
        goal[ids.index(i)] = {
            "id": i,
            "mesh": "cube",
            "pose": _pose(0.55, 0.2, 0.02 + 0.04 * level),
        }
    instance = {
        "domain": "cubes",
        "start": {"domain": "cubes", "objects": start},
        "goal": {"domain": "cubes", "objects": goal},
    }
    path = tmp_path / "tower.json"
    path.write_text(json.dumps(instance))
    out = tmp_path / "obs"
    r = subprocess.run(
        [RIVET, "scene", "render", str(path), "--out", str(out)],
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    assert r.returncode == 0, r.stderr
    r = subprocess.run(
        [RIVET, "solve", "cubes", str(out / "start"), str(out / "goal")],
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    assert r.returncode == 0, r.stderr
    plan = json.loads(r.stdout)
    assert plan["status"] == "ok" and plan["steps"]
    d = domains.load("cubes")
    problems = check_order(d, instance["start"], plan["steps"], instance["goal"], physics=False)
    assert problems == [], problems
    assert "perceive" in r.stderr  # timings go to stderr, the plan alone to stdout
