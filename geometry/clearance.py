"""Whether the gripper clears a set of meshes: its fingers, linkage and palm as boxes in the
TCP frame (`geometry.robot.FingerModel`, at a jaw opening and fingertip depth) against the
meshes' triangles, by the separating axis theorem, with world bounding boxes for a quick
rejection. The grasp planner (`geometry.grasps`) asks it at the pick and at the place."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

from geometry.robot import FingerModel


def boxes_hit_triangles(
    centre: np.ndarray, half: np.ndarray, R: np.ndarray, tris: np.ndarray
) -> bool:
    """True when the box (centre (3,), half extents (3,), axes R (3, 3) columns, world) overlaps
    any triangle of `tris` (n, 3, 3), world."""
    n = len(tris)
    return _pairs_overlap(np.broadcast_to(centre, (n, 3)), np.broadcast_to(half, (n, 3)), R, tris)


def _pairs_overlap(
    centres: np.ndarray, halves: np.ndarray, R: np.ndarray, tris: np.ndarray
) -> bool:
    """Whether any box k (centre centres[k], half extents halves[k], axes R) overlaps its
    triangle tris[k] (separating axis theorem, all pairs at once)."""
    if len(tris) == 0:
        return False
    v = (tris - centres[:, None, :]) @ R  # (n, 3, 3) in the box frame
    # Box face axes.
    lo, hi = v.min(axis=1), v.max(axis=1)
    keep = ((lo <= halves) & (hi >= -halves)).all(axis=1)
    if not keep.any():
        return False
    v, half = v[keep], halves[keep]
    e = np.stack([v[:, 1] - v[:, 0], v[:, 2] - v[:, 1], v[:, 0] - v[:, 2]], axis=1)  # (n, 3, 3)
    # Triangle normal.
    n = _cross(e[:, 0], e[:, 1])
    p = np.einsum("nk,nk->n", n, v[:, 0])
    r = np.einsum("nk,nk->n", np.abs(n), half)
    sep = np.abs(p) > r
    # Nine edge × axis cross products, all at once: a[n, i, j] = e_i × (box axis j).
    ex, ey, ez = e[..., 0], e[..., 1], e[..., 2]  # (n, 3)
    a = np.zeros((len(e), 3, 3, 3))
    a[:, :, 0, 1], a[:, :, 0, 2] = ez, -ey
    a[:, :, 1, 0], a[:, :, 1, 2] = -ez, ex
    a[:, :, 2, 0], a[:, :, 2, 1] = ey, -ex
    proj = np.einsum("nijk,nvk->nijv", a, v)  # (n, 3, 3, 3 vertices)
    r = np.einsum("nijk,nk->nij", np.abs(a), half)  # (n, 3, 3)
    sep |= ((proj.min(axis=3) > r) | (proj.max(axis=3) < -r)).any(axis=(1, 2))
    return bool((~sep).any())


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (n, 3) arrays (np.cross without its per-call overhead)."""
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )


def world_triangles(mesh: trimesh.Trimesh, pose: np.ndarray) -> np.ndarray:
    tris = np.asarray(mesh.vertices)[np.asarray(mesh.faces)]  # (n, 3, 3), plain arrays
    return tris @ pose[:3, :3].T + pose[:3, 3]


@dataclass(frozen=True)
class Triangles:
    """A mesh's triangles in the world, with their bounding box for a quick rejection."""

    tris: np.ndarray  # (n, 3, 3)
    lo: np.ndarray  # (3,)
    hi: np.ndarray  # (3,)
    tri_lo: np.ndarray  # (n, 3) per triangle
    tri_hi: np.ndarray  # (n, 3)

    @classmethod
    def of(cls, mesh: trimesh.Trimesh, pose: np.ndarray) -> Triangles:
        tris = world_triangles(mesh, pose)
        tri_lo, tri_hi = tris.min(axis=1), tris.max(axis=1)
        return cls(tris, tri_lo.min(axis=0), tri_hi.max(axis=0), tri_lo, tri_hi)


@functools.lru_cache(maxsize=4096)
def _box_arrays(
    fingers: FingerModel, gap: float, tip: float, margin: float
) -> tuple[np.ndarray, np.ndarray]:
    """`fingers.boxes(...)` as arrays: centres (n, 3) and half extents (n, 3), TCP frame."""
    boxes = fingers.boxes(gap, tip, margin)
    return np.array([c for c, _ in boxes]), np.array([h for _, h in boxes])


def _gripper_boxes(
    T_world_tcp: np.ndarray, gap: float, tip: float, margin: float, fingers: FingerModel
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The gripper's boxes in the world: centres, half extents, axes, and their world AABBs
    (lo, hi)."""
    R = T_world_tcp[:3, :3]
    centres, halves = _box_arrays(fingers, gap, tip, margin)
    c = centres @ R.T + T_world_tcp[:3, 3]  # (n, 3) world
    extent = halves @ np.abs(R).T  # (n, 3) the boxes' world AABB half sizes
    return c, halves, R, c - extent, c + extent


def _boxes_hit(boxes: tuple[np.ndarray, ...], t: Triangles) -> bool:
    """Whether any of the gripper's `boxes` (`_gripper_boxes`) overlaps a triangle of `t`."""
    c, halves, R, lo, hi = boxes
    near = ((hi >= t.lo) & (lo <= t.hi)).all(axis=1)
    if not near.any():
        return False
    idx = np.flatnonzero(near)
    close = (  # (box, triangle) pairs whose world AABBs overlap
        (t.tri_hi[None] >= lo[idx, None]) & (t.tri_lo[None] <= hi[idx, None])
    ).all(axis=2)
    b, k = np.nonzero(close)
    return _pairs_overlap(c[idx[b]], halves[idx[b]], R, t.tris[k])


def gripper_hits(
    T_world_tcp: np.ndarray,
    gap: float,
    tip: float,
    margin: float,
    triangle_sets: Sequence[Triangles],
    fingers: FingerModel,
) -> bool:
    """Whether the gripper's boxes hit any of `triangle_sets` (`first_hit` says which)."""
    return first_hit(T_world_tcp, gap, tip, margin, triangle_sets, fingers) >= 0


def first_hit(
    T_world_tcp: np.ndarray,
    gap: float,
    tip: float,
    margin: float,
    triangle_sets: Sequence[Triangles],
    fingers: FingerModel,
) -> int:
    boxes = _gripper_boxes(T_world_tcp, gap, tip, margin, fingers)
    for i, tris in enumerate(triangle_sets):
        if _boxes_hit(boxes, tris):
            return i
    return -1


__all__ = ["Triangles", "boxes_hit_triangles", "first_hit", "gripper_hits", "world_triangles"]
