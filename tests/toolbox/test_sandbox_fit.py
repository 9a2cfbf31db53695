"""The toolbox must run in the sandbox: read-only root, writable /tmp only, no network."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

SCRIPT = textwrap.dedent(
    """
    import numpy as np, trimesh
    from tests.toolbox.conftest import top_down_camera
    from toolbox import Shape, collisions, pose_from_xyz_yaw, register_mesh_to_segment, render_scene
    cube = trimesh.creation.box((0.05, 0.05, 0.05))
    recs = [{"id": "a", "mesh": "cube", "pose": pose_from_xyz_yaw(0.01, 0, 0.025, 0.3)}]
    cam = top_down_camera(0.6)
    out = render_scene(recs, {"cube": cube}, cam)
    register_mesh_to_segment(cube, out["depth"], out["mask"] == 0, cam)
    assert collisions(recs, {"cube": Shape.from_mesh(cube)}) == []
    print("ok")
    """
)


@pytest.mark.slow
def test_toolbox_writes_nothing_to_home(tmp_path: Path):
    home = tmp_path / "home"
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("XDG_", "MESA_"))}
    env |= {"HOME": str(home), "PYTHONDONTWRITEBYTECODE": "1"}
    root = Path(__file__).resolve().parents[2]
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "ok"
    assert list(home.rglob("*")) == [], "the toolbox wrote under $HOME"
