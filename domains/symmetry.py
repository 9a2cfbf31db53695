"""Symmetry groups of object meshes, as lists of 4×4 object-frame transforms.

A symmetry `S` maps the mesh onto itself: `mesh(S @ v) == mesh(v)`, so the poses `T` and
`T @ S` of an object are indistinguishable. Groups are described in the catalogue as small
dicts and expanded here; every group contains the identity first. Only proper rotations
appear: a mirror image is not a pose a robot can reach.

Descriptions (``centre`` is the fixed point in the object frame [m], default the origin):
- ``{"kind": "identity"}``
- ``{"kind": "cyclic", "n": n, "axis": "z"}``: n rotations about the axis.
- ``{"kind": "dihedral", "n": n, "axis": "z"}``: the cyclic group plus n half-turns about
  axes perpendicular to `axis` (a prism that may lie upside down).
- ``{"kind": "cube"}``: the 24 rotations of a cube.
- ``{"kind": "revolution", "axis": "z", "flip": bool, "steps": k}``: a body of revolution,
  sampled every 360/k degrees (default k = 360); with ``flip`` also turned upside down.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from typing import Any

import numpy as np

_AXES = {"x": np.array([1.0, 0, 0]), "y": np.array([0, 1.0, 0]), "z": np.array([0, 0, 1.0])}


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix (3, 3) about a unit `axis` by `angle` [rad] (Rodrigues)."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def _perpendicular(axis: np.ndarray) -> np.ndarray:
    other = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    p = np.cross(axis, other)
    return p / np.linalg.norm(p)


def _rotations(desc: Mapping[str, Any]) -> list[np.ndarray]:
    kind = desc.get("kind")
    axis = _AXES[desc.get("axis", "z")]
    if kind == "identity":
        return [np.eye(3)]
    if kind in ("cyclic", "dihedral"):
        n = int(desc["n"])
        rots = [rotation(axis, 2 * np.pi * k / n) for k in range(n)]
        if kind == "dihedral":
            p = _perpendicular(axis)
            rots += [rotation(rotation(axis, np.pi * k / n) @ p, np.pi) for k in range(n)]
        return rots
    if kind == "cube":
        rots = []
        for perm in itertools.permutations(range(3)):
            for signs in itertools.product((1.0, -1.0), repeat=3):
                r = np.zeros((3, 3))
                for row, (col, sign) in enumerate(zip(perm, signs, strict=True)):
                    r[row, col] = sign
                if np.linalg.det(r) > 0:
                    rots.append(r)
        rots.sort(key=lambda r: -np.trace(r))  # identity first
        return rots
    if kind == "revolution":
        steps = int(desc.get("steps", 360))
        rots = [rotation(axis, 2 * np.pi * k / steps) for k in range(steps)]
        if desc.get("flip", False):
            flip = rotation(_perpendicular(axis), np.pi)
            rots += [r @ flip for r in rots]
        return rots
    raise ValueError(f"unknown symmetry kind {kind!r}")


def group(desc: Mapping[str, Any]) -> np.ndarray:
    """The symmetry transforms of a description, shape (n, 4, 4), identity first."""
    centre = np.asarray(desc.get("centre", (0.0, 0.0, 0.0)), dtype=float)
    out = []
    for r in _rotations(desc):
        t = np.eye(4)
        t[:3, :3] = np.round(r, 12)
        t[:3, 3] = centre - t[:3, :3] @ centre
        out.append(t)
    return np.stack(out)
