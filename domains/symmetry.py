"""Symmetry groups of object meshes, as lists of 4×4 object-frame transforms.

A symmetry `S` maps the mesh onto itself: `mesh(S @ v) == mesh(v)`, so the poses `T` and
`T @ S` of an object are indistinguishable. Groups are described in the catalogue as small
dicts and expanded here; every group contains the identity first. Only proper rotations
appear: a mirror image is not a pose a robot can reach. The rotations are `contracts.se3`'s.

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

from collections.abc import Mapping
from typing import Any

import numpy as np

from contracts import se3

_AXES = {"x": np.array([1.0, 0, 0]), "y": np.array([0, 1.0, 0]), "z": np.array([0, 0, 1.0])}


def _perpendicular(axis: np.ndarray) -> np.ndarray:
    other = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    p = np.cross(axis, other)
    return p / np.linalg.norm(p)


def _cube_order(r: np.ndarray) -> tuple:
    """Identity first, then by decreasing trace; within a trace, by the signed permutation
    (column of each row's ±1, then its sign): the order the catalogues' groups have always
    had, so that ties between equivalent poses resolve as before."""
    cols = tuple(int(np.argmax(np.abs(row))) for row in r)
    return (-np.trace(r), cols, tuple(bool(row[c] < 0) for row, c in zip(r, cols, strict=True)))


def _rotations(desc: Mapping[str, Any]) -> list[np.ndarray]:
    kind = desc.get("kind")
    axis = _AXES[desc.get("axis", "z")]
    if kind == "identity":
        return [np.eye(3)]
    if kind in ("cyclic", "dihedral"):
        n = int(desc["n"])
        rots = [se3.rotation_about(axis, 2 * np.pi * k / n) for k in range(n)]
        if kind == "dihedral":
            p = _perpendicular(axis)
            rots += [
                se3.rotation_about(se3.rotation_about(axis, np.pi * k / n) @ p, np.pi)
                for k in range(n)
            ]
        return rots
    if kind == "cube":
        return sorted((g[:3, :3] for g in se3.cube_group()), key=_cube_order)
    if kind == "revolution":
        steps = int(desc.get("steps", 360))
        rots = [se3.rotation_about(axis, 2 * np.pi * k / steps) for k in range(steps)]
        if desc.get("flip", False):
            flip = se3.rotation_about(_perpendicular(axis), np.pi)
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
