"""Shared scenes for the toolbox tests: cameras, meshes."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh


def look_at_camera(eye, target, *, width=320, height=240, f=300.0, up=(0.0, 0.0, 1.0)) -> dict:
    """An OpenCV camera at `eye` looking at `target` (x right, y down, z forward)."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, float))
    if np.linalg.norm(x) < 1e-9:  # looking straight down: image right = world +x
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye
    K = np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])
    return {"width": width, "height": height, "K": K, "T_world_camera": T}


def top_down_camera(height_m=1.0, **kw) -> dict:
    """Camera above the origin looking straight down (image right = +x, image down = -y)."""
    return look_at_camera((0.0, 0.0, height_m), (0.0, 0.0, 0.0), **kw)


def prism(vertices_2d, thickness) -> trimesh.Trimesh:
    """Closed prism over a convex polygon (counter-clockwise), from z = 0 to z = thickness."""
    V = np.asarray(vertices_2d, float)
    n = len(V)
    verts = np.vstack([np.c_[V, np.zeros(n)], np.c_[V, np.full(n, thickness)]])
    faces = []
    for i in range(1, n - 1):
        faces.append([0, i + 1, i])  # bottom, facing -z
        faces.append([n, n + i, n + i + 1])  # top, facing +z
    for i in range(n):
        j = (i + 1) % n
        faces.append([i, j, n + j])
        faces.append([i, n + j, n + i])
    mesh = trimesh.Trimesh(verts, np.array(faces), process=True)
    assert mesh.is_watertight and mesh.volume > 0
    return mesh


def l_block() -> trimesh.Trimesh:
    """An asymmetric L-shaped part (no proper symmetry), about 10 cm across."""
    a = trimesh.creation.box((0.10, 0.05, 0.03))
    b = trimesh.creation.box((0.03, 0.05, 0.07))
    b.apply_translation((0.035, 0.0, 0.05))
    c = trimesh.creation.box((0.02, 0.03, 0.02))
    c.apply_translation((-0.04, 0.035, 0.0))
    return trimesh.util.concatenate([a, b, c])


@pytest.fixture
def cube() -> trimesh.Trimesh:
    return trimesh.creation.box((0.05, 0.05, 0.05))
