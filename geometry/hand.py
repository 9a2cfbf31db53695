"""The robot's hand: top-down parallel-jaw grasps for the Robotiq 2F-85 on the FR3, from an
object's mesh, its pose and its target — the one model the executor, the plan checks, the
generators' construction planner and the programs (through `toolbox.hand`) all use.

Design rule: a grasp is chosen once per transfer and held rigidly from pick to place, so it is
planned in the object's frame and checked at both ends. Candidates come from pairs of
antiparallel mesh faces that are vertical at the pick pose and no more than the jaws' stroke
apart; each pair gives two wrist yaws (the gripper is symmetric under a half turn) and the
object's symmetries give several equivalent place poses. A candidate is kept when the fingers,
opened for the approach, clear the object itself, the table and every neighbour at the pick
and at the place. Reachability (the wrist's joint limits) is decided by the caller's IK.

Gripper volumes are boxes in the TCP frame (z along the approach, y along the closing
direction), measured from the menagerie 2F-85's collision geometry (see `FingerModel`); the
jaws' stroke (`STROKE`) was measured in simulation from the same model, and
`tests/sim/test_robot.py` measures it again and compares. No simulator is needed here.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trimesh

from contracts import se3
from geometry.convex import Body, Piece, body_separation, place
from geometry.plans import Workspace
from geometry.tolerances import TOLERANCES

WORKSPACE = Workspace(x=(0.25, 0.75), y=(-0.35, 0.35), reach=0.78)
"""Where the FR3 reaches top-down with the 2F-85: every point of an object it picks or places
must lie inside (the plan checks refuse a step outside, and generators keep scenes inside)."""
PLACEMENT = Workspace(x=(0.32, 0.68), y=(-0.27, 0.27), reach=0.72)
"""Where the task's scenes keep their objects, inside `WORKSPACE`: the generators draw every
object inside it, and it is where a plan puts objects aside with the arm comfortably within
reach (near the workspace's edge the wrist runs out of joint range)."""
PLACEMENT_SPREAD = (0.0015, 0.0015)
"""(gap, max shift) [m]: a tightly packed goal is placed reliably once its gaps are opened to
`gap`, moving no part more than `max shift` (the executor hits a target to a few tenths of a
millimetre)."""
MAX_GRASP_WIDTH = 0.080  # [m] the widest face pair the jaws take (they open to 85 mm)
VERTICAL_TOL = TOLERANCES.face_vertical
ANTIPARALLEL_TOL = TOLERANCES.face_antiparallel
YAW_ONLY_TOL = TOLERANCES.yaw_only


@dataclass(frozen=True, kw_only=True)
class GripperStroke:
    """How the 2F-85's jaws move with its control: the pads travel on an arc, so the
    fingertips' depth along the TCP's z axis depends on the opening.

    Attributes:
        ctrl: (n,) increasing control values (0 fully open … 255 fully closed).
        gap: (n,) distance between the pads' inner faces [m], decreasing.
        tip: (n,) fingertip depth along the TCP z axis, from the TCP [m].
        pad_height: contact height of a pad, from its tip towards the palm [m].
        pad_width: pad width across the closing direction [m].
        max_gap: the widest opening [m].
    """

    ctrl: np.ndarray
    gap: np.ndarray
    tip: np.ndarray
    pad_height: float = 0.0375
    pad_width: float = 0.022
    max_gap: float = 0.085

    def ctrl_for_gap(self, gap: float) -> float:
        """Control value that opens the jaws to `gap` [m] (clipped to the stroke)."""
        return float(np.interp(gap, self.gap[::-1], self.ctrl[::-1]))

    def tip_at_gap(self, gap: float) -> float:
        """Fingertip depth along the TCP z axis [m] when the jaws are `gap` [m] apart."""
        return float(np.interp(gap, self.gap[::-1], self.tip[::-1]))


STROKE = GripperStroke(
    ctrl=np.linspace(0.0, 255.0, 18),
    gap=np.array(
        [0.085166, 0.080818, 0.076317, 0.071674, 0.066897, 0.061996, 0.056981, 0.051862,
         0.046649, 0.041353, 0.035984, 0.030554, 0.025073, 0.019552, 0.014003, 0.008437,
         0.002864, 0.000423]
    ),
    tip=np.array(
        [0.004525, 0.006193, 0.007764, 0.009231, 0.010592, 0.011844, 0.012983, 0.014006,
         0.014912, 0.015698, 0.016361, 0.016901, 0.017315, 0.017602, 0.017763, 0.017794,
         0.017698, 0.017626]
    ),
)  # fmt: skip
"""The menagerie 2F-85's stroke, measured in simulation (`sim.robot.measure_stroke`)."""


@dataclass(frozen=True, kw_only=True)
class FingerModel:
    """Boxes around the 2F-85's fingers and palm, in the TCP frame [m].

    Measured from the menagerie model's collision geometry over the whole stroke. Each finger
    is a stack of boxes, `segments`, given as (from, to) height above the fingertip, how far
    the finger reaches outwards beyond its pad's contact face, and its half width across the
    closing direction. From `linkage_from` up to `palm_from` the couplers and drivers reach out
    to at least `linkage_outer` from the centre line (they splay as the jaws close). Above
    that, `palm` boxes (from, to, x_min, x_max, y_min, y_max) in the TCP frame: the gripper's
    base, then the FR3's link 7, which is rigid with the TCP and juts out on one side (so the
    two wrist yaws of a grasp differ); the last box reaches 1 m up and stands for the arm.
    """

    segments: tuple[tuple[float, float, float, float], ...] = (
        (0.000, 0.040, 0.017, 0.012),
        (0.040, 0.060, 0.033, 0.017),
    )
    linkage_from: float = 0.060
    linkage_outer: float = 0.064
    linkage_depth: float = 0.0315
    linkage_half_width: float = 0.020
    palm_from: float = 0.120
    palm: tuple[tuple[float, float, float, float, float, float], ...] = (
        (0.120, 0.160, -0.038, 0.038, -0.038, 0.038),
        (0.160, 1.000, -0.082, 0.042, -0.042, 0.082),
    )
    clearances: tuple[float, ...] = (0.008, 0.004)  # jaw opening beyond the object's width,
    # per side, for the approach and the release: the first that clears the neighbours is used
    min_clearance: float = 0.0025  # the least per-side opening allowed for wide objects
    tip_margin: float = 0.003  # fingertips stay this far above whatever is below them
    min_contact: float = 0.008  # the least pad contact height accepted [m]
    high_contact: float = 0.015  # contact height of the alternative grasp high on a face [m]
    ceiling: tuple[tuple[float, float], ...] = (
        (0.006, 0.0748),
        (0.025, 0.0655),
        (0.046, 0.0571),
        (0.067, 0.0549),
        (0.085, 0.0375),
    )
    """(jaw gap, free height above the fingertips between the fingers) [m]: above it the spring
    links and the base close the space between the jaws; the wider open, the lower."""
    inner_half_width: float = 0.025

    def ceiling_at(self, gap: float) -> float:
        """Free height between the fingers above their tips at jaw opening `gap` [m]."""
        gaps, heights = zip(*self.ceiling, strict=True)
        return float(np.interp(gap, gaps, heights))

    def boxes(self, gap: float, tip: float, margin: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """Boxes (centre (3,), half extents (3,)) in the TCP frame (z towards the fingertips)
        for jaws `gap` apart with the fingertips at depth `tip`, inflated by `margin`."""
        out = []
        y0 = gap / 2
        layers = [(lo, hi, y0, y0 + depth, hw) for lo, hi, depth, hw in self.segments]
        outer = max(y0 + self.linkage_depth, self.linkage_outer)
        layers.append((self.linkage_from, self.palm_from, y0, outer, self.linkage_half_width))
        for lo, hi, y_in, y_out, hw in layers:
            for side in (-1.0, 1.0):
                centre = np.array([0.0, side * (y_in + y_out) / 2, tip - (lo + hi) / 2])
                half = np.array([hw, (y_out - y_in) / 2, (hi - lo) / 2]) + margin
                out.append((centre, half))
        ceiling = self.ceiling_at(gap)
        centre = np.array([0.0, 0.0, tip - ceiling - 0.5])
        half = np.array([self.inner_half_width, y0, 0.5]) + np.array([margin, 0.0, margin])
        out.append((centre, half))
        for lo, hi, x0, x1, y_lo, y_hi in self.palm:
            centre = np.array([(x0 + x1) / 2, (y_lo + y_hi) / 2, tip - (lo + hi) / 2])
            half = np.array([(x1 - x0) / 2, (y_hi - y_lo) / 2, (hi - lo) / 2]) + margin
            out.append((centre, half))
        return out


@dataclass(frozen=True, kw_only=True)
class Obstacle:
    """A neighbour at a pose: its id, mesh (object frame) and T_world_object."""

    id: str
    mesh: trimesh.Trimesh
    pose: np.ndarray


@dataclass(frozen=True, kw_only=True)
class Grasp:
    """A top-down grasp held from pick to place.

    Attributes:
        T_object_tcp: TCP pose in the object's frame (4, 4).
        width: distance between the gripped faces [m].
        open_gap: jaw opening for the approach and the release [m].
        symmetry: index of the symmetry `S` the object is placed with: it ends at target @ S.
        pick_tcp: TCP pose at the grasp (4, 4), world.
        place_tcp: TCP pose at the release (4, 4), world.
        contact_area: pad contact area on each face [m²].
        transfer_yaw: rotation of the wrist from pick to place [rad], signed.
        margin: clearance from the neighbours that was verified [m].
        score: how good the grasp is (larger is better; grasps come best first).
    """

    T_object_tcp: np.ndarray
    width: float
    open_gap: float
    symmetry: int
    pick_tcp: np.ndarray
    place_tcp: np.ndarray
    contact_area: float
    transfer_yaw: float
    margin: float
    score: float = 0.0


@dataclass(frozen=True, kw_only=True)
class GraspReport:
    """The grasps found for one move and why the other candidates were dropped.

    Attributes:
        grasps: the feasible grasps (`Grasp`), best first; empty when there is none.
        rejected: why candidates were dropped (a reason in words) → how many.
        blockers: neighbour id → how many candidates it blocked (at the pick or the place).
    """

    grasps: tuple[Grasp, ...]
    rejected: dict[str, int] = field(default_factory=dict)
    blockers: dict[str, int] = field(default_factory=dict)

    def summary(self) -> str:
        """One line: why candidates were dropped, the most frequent reason first."""
        if not self.rejected:
            return "no antiparallel vertical face pair on the mesh"
        parts = [f"{n} {why}" for why, n in sorted(self.rejected.items(), key=lambda kv: -kv[1])]
        return "candidates rejected: " + ", ".join(parts)


# -- mesh analysis --------------------------------------------------------------------------


@dataclass(frozen=True)
class _Region:
    normal: np.ndarray  # (3,) object frame, outward
    offset: float  # plane: normal · x = offset
    triangles: np.ndarray  # (k, 3, 3) object frame


_REGION_CACHE: dict[int, tuple[trimesh.Trimesh, tuple[_Region, ...]]] = {}


def _regions(mesh: trimesh.Trimesh) -> tuple[_Region, ...]:
    """Planar regions of the mesh (trimesh facets and lone faces), cached per mesh object."""
    hit = _REGION_CACHE.get(id(mesh))
    if hit is not None and hit[0] is mesh:
        return hit[1]
    if len(_REGION_CACHE) > 256:
        _REGION_CACHE.clear()
    regions = _compute_regions(mesh)
    _REGION_CACHE[id(mesh)] = (mesh, regions)
    return regions


def _compute_regions(mesh: trimesh.Trimesh) -> tuple[_Region, ...]:
    regions = []
    in_facet = np.zeros(len(mesh.faces), dtype=bool)
    groups = [np.asarray(f) for f in mesh.facets]
    for f in groups:
        in_facet[f] = True
    groups += [np.array([i]) for i in np.flatnonzero(~in_facet)]
    for faces in groups:
        areas = mesh.area_faces[faces]
        n = (mesh.face_normals[faces] * areas[:, None]).sum(axis=0)
        n /= np.linalg.norm(n)
        tris = mesh.vertices[mesh.faces[faces]]
        regions.append(_Region(n, float(np.mean(tris.reshape(-1, 3) @ n)), tris))
    return tuple(regions)


def _point_in_triangles(p: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Which points (m, 2) lie inside any of the 2-D triangles (k, 3, 2)."""
    inside = np.zeros(len(p), dtype=bool)
    for a, b, c in tris:
        v0, v1 = c - a, b - a
        d00, d01, d11 = v0 @ v0, v0 @ v1, v1 @ v1
        denom = d00 * d11 - d01 * d01
        if abs(denom) < 1e-14:
            continue
        w = p - a
        d20, d21 = w @ v0, w @ v1
        u = (d11 * d20 - d01 * d21) / denom
        v = (d00 * d21 - d01 * d20) / denom
        inside |= (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9)
    return inside


# -- collision of boxes with triangles (separating axis theorem) ----------------------------


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


def _world_triangles(mesh: trimesh.Trimesh, pose: np.ndarray) -> np.ndarray:
    tris = np.asarray(mesh.vertices)[np.asarray(mesh.faces)]  # (n, 3, 3), plain arrays
    return tris @ pose[:3, :3].T + pose[:3, 3]


@dataclass(frozen=True)
class _Triangles:
    """A mesh's triangles in the world, with their bounding box for a quick rejection."""

    tris: np.ndarray  # (n, 3, 3)
    lo: np.ndarray  # (3,)
    hi: np.ndarray  # (3,)
    tri_lo: np.ndarray  # (n, 3) per triangle
    tri_hi: np.ndarray  # (n, 3)

    @classmethod
    def of(cls, mesh: trimesh.Trimesh, pose: np.ndarray) -> _Triangles:
        tris = _world_triangles(mesh, pose)
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


def _boxes_hit(boxes: tuple[np.ndarray, ...], t: _Triangles) -> bool:
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


def _gripper_hits(
    T_world_tcp: np.ndarray,
    gap: float,
    tip: float,
    margin: float,
    triangle_sets: Sequence[_Triangles],
    fingers: FingerModel,
) -> bool:
    boxes = _gripper_boxes(T_world_tcp, gap, tip, margin, fingers)
    return any(_boxes_hit(boxes, t) for t in triangle_sets)


# -- candidates -----------------------------------------------------------------------------


_yaw_of = se3.yaw


def _wrap(a: float) -> float:
    return float((a + np.pi) % (2 * np.pi) - np.pi)


@dataclass(frozen=True)
class _FacePair:
    closing: np.ndarray  # (3,) world, horizontal, from face B to face A
    width: float
    centre: np.ndarray  # (3,) world: mid-plane point at the chosen contact
    tip_z: float  # world z of the fingertips at contact
    contact_area: float


_PAIRS: dict[Any, tuple[trimesh.Trimesh, list[_FacePair], dict[str, int]]] = {}
_PAIRS_MAX = 4096


def _face_pairs(
    mesh: trimesh.Trimesh,
    T_pick: np.ndarray,
    max_width: float,
    fingers: FingerModel,
    table: GripperStroke,
    rejected: dict[str, int],
) -> list[_FacePair]:
    """The face pairs the jaws may take and where, for the mesh at `T_pick` (cached on the
    mesh and the pose: a planner asks about the same object where it lies many times)."""
    key = (id(mesh), _pose_key(T_pick), max_width, fingers, id(table))
    got = _PAIRS.get(key)
    if got is None or got[0] is not mesh:
        why: dict[str, int] = {}
        got = (mesh, _find_face_pairs(mesh, T_pick, max_width, fingers, table, why), why)
        if len(_PAIRS) >= _PAIRS_MAX:
            _PAIRS.clear()
        _PAIRS[key] = got  # the mesh is kept with it, so its id is not reused meanwhile
    for k, n in got[2].items():
        rejected[k] = rejected.get(k, 0) + n
    return got[1]


def _find_face_pairs(
    mesh: trimesh.Trimesh,
    T_pick: np.ndarray,
    max_width: float,
    fingers: FingerModel,
    table: GripperStroke,
    rejected: dict[str, int],
) -> list[_FacePair]:
    R, t = T_pick[:3, :3], T_pick[:3, 3]
    regions = _regions(mesh)
    normals = np.array([r.normal for r in regions]) @ R.T  # world
    vertical = np.abs(normals[:, 2]) < np.sin(VERTICAL_TOL)
    idx = np.flatnonzero(vertical)
    obj_tris = _world_triangles(mesh, T_pick)
    bottom = float(obj_tris[..., 2].min())
    com = R @ np.asarray(mesh.center_mass if mesh.is_volume else mesh.centroid) + t
    pairs = []
    for ia in idx:
        for ib in idx:
            if ib <= ia:
                continue
            na, nb = normals[ia], normals[ib]
            if na @ nb > -np.cos(ANTIPARALLEL_TOL):
                continue
            n = na - nb
            n[2] = 0.0
            n /= np.linalg.norm(n)
            tri_a = regions[ia].triangles @ R.T + t
            tri_b = regions[ib].triangles @ R.T + t
            width = float(np.mean(tri_a.reshape(-1, 3) @ n) - np.mean(tri_b.reshape(-1, 3) @ n))
            if width <= 0.002:
                continue  # not enclosing the object
            if width > max_width:
                rejected["too wide"] = rejected.get("too wide", 0) + 1
                continue
            found = _contact_patch(n, width, tri_a, tri_b, obj_tris, bottom, com, fingers, table)
            if not found:
                rejected["too small a contact patch"] = (
                    rejected.get("too small a contact patch", 0) + 1
                )
            pairs.extend(found)
    return pairs


def _contact_patch(
    n: np.ndarray,
    width: float,
    tri_a: np.ndarray,
    tri_b: np.ndarray,
    obj_tris: np.ndarray,
    bottom: float,
    com: np.ndarray,
    fingers: FingerModel,
    table: GripperStroke,
) -> list[_FacePair]:
    """Where the pads may touch a face pair: the overlap of both faces seen along `n`, as low
    as the fingers may go (and, as an alternative, high on the faces), centred on the object's
    centre of mass where the overlap allows."""
    u_axis = np.cross(np.array([0.0, 0.0, 1.0]), n)

    def to2d(tris: np.ndarray) -> np.ndarray:
        return np.stack([tris @ u_axis, tris[..., 2]], axis=-1)  # (k, 3, 2)

    a2, b2 = to2d(tri_a), to2d(tri_b)
    lo = np.maximum(a2.reshape(-1, 2).min(0), b2.reshape(-1, 2).min(0))
    hi = np.minimum(a2.reshape(-1, 2).max(0), b2.reshape(-1, 2).max(0))
    # A facet of a curved side may be a narrow strip: the pads then touch along a line.
    if hi[0] - lo[0] < 0.002 or hi[1] - lo[1] < fingers.min_contact:
        return []
    step = 0.001
    step_u = min(step, (hi[0] - lo[0]) / 4)
    us = np.arange(lo[0] + step_u / 2, hi[0], step_u)
    zs = np.arange(lo[1] + step / 2, hi[1], step)
    if len(us) == 0 or len(zs) == 0:
        return []
    grid = np.stack(np.meshgrid(us, zs), axis=-1).reshape(-1, 2)
    mask = (_point_in_triangles(grid, a2) & _point_in_triangles(grid, b2)).reshape(len(zs), len(us))
    rows = np.flatnonzero(mask.any(axis=1))
    if len(rows) == 0:
        return []
    z_lo = max(float(zs[rows[0]]) - step / 2, bottom) + fingers.tip_margin
    z_hi = float(zs[rows[-1]]) + step / 2
    if z_hi - z_lo < fingers.min_contact:
        return []
    # The lowest grip covers most of the face; a grip high on the face keeps the fingers'
    # linkage above a tall neighbour.
    heights = [z_lo]
    # Low enough, but with the object's top below the linkage between the fingers.
    top = float(obj_tris[..., 2].max())
    gap = width + 2 * max(fingers.clearances)
    z_ceiling = top - fingers.ceiling_at(gap) + fingers.tip_margin
    if z_lo + 0.002 < z_ceiling <= z_hi - fingers.min_contact:
        heights.append(z_ceiling)
    if z_hi - fingers.high_contact > max(heights) + 0.005:
        heights.append(z_hi - fingers.high_contact)
    mid_plane = 0.5 * (np.mean(tri_a.reshape(-1, 3) @ n) + np.mean(tri_b.reshape(-1, 3) @ n))
    u_com = float(com @ u_axis)
    half_pad = table.pad_width / 2
    out = []
    for z_tip in heights:
        z_top = min(z_hi, z_tip + table.pad_height)
        band = (zs >= z_tip) & (zs <= z_top)
        cols = mask[band].all(axis=0)
        if not cols.any():
            continue
        # The contiguous run of columns nearest the centre of mass.
        runs, start = [], None
        for i, c in enumerate([*cols, False]):
            if c and start is None:
                start = i
            elif not c and start is not None:
                runs.append((float(us[start]) - step_u / 2, float(us[i - 1]) + step_u / 2))
                start = None
        runs.sort(key=lambda r: max(r[0] - u_com, u_com - r[1], 0.0))  # nearest the COM first
        for rank, (u0, u1) in enumerate(runs[:3]):
            area = min(u1 - u0, table.pad_width) * (z_top - z_tip)
            if u1 - u0 <= 2 * half_pad:
                positions = [(u0 + u1) / 2]
            else:
                lo_u, hi_u = u0 + half_pad, u1 - half_pad
                u_c = float(np.clip(u_com, lo_u, hi_u))
                positions = [u_c]
                if rank == 0:  # along a long face: off-centre grips dodge a neighbour
                    for u in (lo_u, hi_u, (lo_u + u_c) / 2, (hi_u + u_c) / 2):
                        if all(abs(u - p) > 0.005 for p in positions):
                            positions.append(u)
            for u in positions:
                centre = u * u_axis + mid_plane * n
                centre[2] = z_tip
                out.append(
                    _FacePair(closing=n, width=width, centre=centre, tip_z=z_tip, contact_area=area)
                )
    return out


def _tcp_pose(closing: np.ndarray, centre_xy: np.ndarray, tcp_z: float) -> np.ndarray:
    """Top-down TCP pose: z down, y along `closing` (horizontal)."""
    z = np.array([0.0, 0.0, -1.0])
    y = closing / np.linalg.norm(closing)
    x = np.cross(y, z)
    return se3.make(np.column_stack([x, y, z]), [centre_xy[0], centre_xy[1], tcp_z])


def plan_grasps(
    mesh: trimesh.Trimesh,
    T_pick: np.ndarray,
    T_target: np.ndarray,
    *,
    symmetries: Sequence[np.ndarray] | None = None,
    pick_obstacles: Sequence[Obstacle] = (),
    place_obstacles: Sequence[Obstacle] = (),
    fingers: FingerModel | None = None,
    table_z: float = 0.0,
    max_width: float = MAX_GRASP_WIDTH,
    margins: Sequence[float] = TOLERANCES.grasp_margins,
    max_symmetries: int = 4,
    limit: int | None = None,
) -> GraspReport:
    """Feasible top-down grasps to move `mesh` from `T_pick` to `T_target`, best first.

    Args:
        mesh: the object's mesh in its own frame [m].
        T_pick, T_target: its current and target poses (4, 4).
        symmetries: object-frame transforms S with mesh(S v) = mesh(v); the object may end at
            T_target @ S for any of them. None: the identity only.
        pick_obstacles / place_obstacles: neighbours around the pick and the place.
        table_z: height of the table top [m]; fingertips stay above it.
        max_width: widest face pair the jaws take [m].
        margins: clearances tried against neighbours [m], larger (preferred) first.
        max_symmetries: per face pair and wrist yaw, how many place options (fewest wrist
            rotation first) are checked.
        limit: stop once this many grasps are found (a feasibility test: the grasps returned
            are then not necessarily the best). None: all.
    """
    fingers = fingers or FingerModel()
    table = STROKE
    T_pick = np.asarray(T_pick, dtype=float)
    T_target = np.asarray(T_target, dtype=float)
    syms = [np.eye(4)] if symmetries is None or len(symmetries) == 0 else list(symmetries)
    rejected: dict[str, int] = {}
    blockers: dict[str, int] = {}

    # Place options: the symmetric targets reachable by a rotation about the vertical.
    options = []  # (index, T_place, yaw of pick → place)
    for k, S in enumerate(syms):
        T_place = T_target @ np.asarray(S, dtype=float)
        R_rel = T_place[:3, :3] @ T_pick[:3, :3].T
        if np.arccos(np.clip(R_rel[2, 2], -1.0, 1.0)) > YAW_ONLY_TOL:
            continue
        options.append((k, T_place, _yaw_of(R_rel)))
    if not options:
        return GraspReport(
            grasps=(), rejected={"target tilted from the pick pose (top-down grasp cannot)": 1}
        )

    pairs = _face_pairs(mesh, T_pick, max_width, fingers, table, rejected)
    own_pick = _Triangles.of(mesh, T_pick)
    pick_sets = [_Triangles.of(o.mesh, o.pose) for o in pick_obstacles]
    place_sets = [_Triangles.of(o.mesh, o.pose) for o in place_obstacles]
    T_pick_inv = se3.inverse(T_pick)
    pick_ids = [o.id for o in pick_obstacles]
    place_ids = [o.id for o in place_obstacles]
    grasps: list[Grasp] = []

    def reject(why: str) -> None:
        rejected[why] = rejected.get(why, 0) + 1

    for pair in pairs:
        if pair.tip_z < table_z + fingers.tip_margin - 0.001:
            reject("fingertips below the table")
            continue
        side = (max_width + 0.005 - pair.width) / 2
        tip_contact = table.tip_at_gap(pair.width)
        tcp_z = pair.tip_z + tip_contact  # the TCP sits above the fingertips
        own_hit: dict[tuple[float, float], bool] = {}
        pick_hits: dict[tuple[float, float, float], int] = {}

        def pick_hit(
            flip: float, tcp: np.ndarray, gap: float, reach: float, margin: float, cache=pick_hits
        ) -> int:
            # the pick side does not depend on the place option: check it once per opening
            key = (flip, gap, margin)
            if key not in cache:
                cache[key] = _first_hit(tcp, gap, reach, margin, pick_sets, fingers)
            return cache[key]

        for flip in (1.0, -1.0):
            tcp_pick = _tcp_pose(flip * pair.closing, pair.centre[:2], tcp_z)
            T_obj_tcp = T_pick_inv @ tcp_pick
            ranked = sorted(options, key=lambda o: abs(o[2]))[:max_symmetries]
            for k, T_place, _dyaw in ranked:
                tcp_place = T_place @ T_obj_tcp
                # The widest approach opening that works, from the preferred one down.
                for clearance in fingers.clearances:
                    clearance = min(clearance, side)
                    if clearance < fingers.min_clearance:
                        reject("too wide")
                        break
                    open_gap = pair.width + 2 * clearance
                    reach = max(tip_contact, table.tip_at_gap(open_gap))  # deepest fingertip
                    # The object itself: nothing may stick out into the jaws' path.
                    key = (flip, open_gap)
                    if key not in own_hit:
                        own_hit[key] = _gripper_hits(
                            tcp_pick, pair.width + 0.002, reach, 0.0, [own_pick], fingers
                        ) or _gripper_hits(tcp_pick, open_gap, reach, 0.0, [own_pick], fingers)
                    if own_hit[key]:
                        reject("fingers hit the object itself")
                        continue
                    if tcp_place[2, 3] - reach < table_z + fingers.tip_margin - 0.001:
                        reject("fingertips below the table at the place")
                        break
                    margin, hit = _clear_margin(
                        functools.partial(pick_hit, flip, tcp_pick, open_gap, reach),
                        tcp_place,
                        open_gap,
                        reach,
                        place_sets,
                        margins,
                        fingers,
                    )
                    if margin is None:
                        where, index = hit
                        who = pick_ids[index] if where == "pick" else place_ids[index]
                        reject(f"fingers hit {who!r} at the {where}")
                        blockers[who] = blockers.get(who, 0) + 1
                        continue
                    grasps.append(
                        Grasp(
                            T_object_tcp=T_obj_tcp,
                            width=pair.width,
                            open_gap=open_gap,
                            symmetry=k,
                            pick_tcp=tcp_pick,
                            place_tcp=tcp_place,
                            contact_area=pair.contact_area,
                            transfer_yaw=_wrap(
                                _yaw_of(tcp_place[:3, :3]) - _yaw_of(tcp_pick[:3, :3])
                            ),
                            margin=margin,
                            score=_score(
                                pair, margin, clearance, tcp_pick, tcp_place, T_pick, mesh
                            ),
                        )
                    )
                    break
                if limit is not None and len(grasps) >= limit:
                    break
            if limit is not None and len(grasps) >= limit:
                break
        if limit is not None and len(grasps) >= limit:
            break
    grasps.sort(key=lambda g: -g.score)
    return GraspReport(grasps=tuple(grasps), rejected=rejected, blockers=blockers)


def _clear_margin(
    pick_hit: Callable[[float], int],
    tcp_place: np.ndarray,
    gap: float,
    reach: float,
    place_sets: Sequence[_Triangles],
    margins: Sequence[float],
    fingers: FingerModel,
) -> tuple[float | None, tuple[str, int]]:
    """The largest margin at which the gripper clears all neighbours at both ends, or None and
    (where, index) of a neighbour hit at the smallest margin. `pick_hit(margin)`: the index of
    the first neighbour hit at the pick, -1 for none."""
    hit = ("pick", -1)
    for margin in margins:
        index = pick_hit(margin)
        if index >= 0:
            hit = ("pick", index)
            continue
        index = _first_hit(tcp_place, gap, reach, margin, place_sets, fingers)
        if index >= 0:
            hit = ("place", index)
            continue
        return float(margin), hit
    return None, hit


def _first_hit(
    T_world_tcp: np.ndarray,
    gap: float,
    tip: float,
    margin: float,
    triangle_sets: Sequence[_Triangles],
    fingers: FingerModel,
) -> int:
    boxes = _gripper_boxes(T_world_tcp, gap, tip, margin, fingers)
    for i, tris in enumerate(triangle_sets):
        if _boxes_hit(boxes, tris):
            return i
    return -1


def _score(
    pair: _FacePair,
    margin: float,
    clearance: float,
    tcp_pick: np.ndarray,
    tcp_place: np.ndarray,
    T_pick: np.ndarray,
    mesh: trimesh.Trimesh,
) -> float:
    """Higher is better: roomy clearance and opening, a large contact patch, little wrist rotation, a grip
    near the centre of mass."""
    com = T_pick[:3, :3] @ np.asarray(mesh.center_mass if mesh.is_volume else mesh.centroid)
    com += T_pick[:3, 3]
    off_com = float(np.linalg.norm(com[:2] - tcp_pick[:2, 3]))
    dyaw = abs(_wrap(_yaw_of(tcp_place[:3, :3]) - _yaw_of(tcp_pick[:3, :3])))
    return 1000.0 * margin + 2.0 * min(pair.contact_area / 4e-4, 1.0) - 1.0 * dyaw - 20.0 * off_com


# -- whole moves ----------------------------------------------------------------------------

NEAR = 0.2  # neighbours farther than this (horizontally) from the object cannot be hit [m]
UP = np.array([0.0, 0.0, 1.0])  # the vertical sweep above a pick or a place [m]


@dataclass(frozen=True, kw_only=True)
class MoveVerdict:
    """Whether the robot can make a move; if not, why, and the neighbours in the way.

    Attributes:
        ok: True when some grasp makes the move.
        blockers: when not `ok`, the ids (str) of the neighbours in the way, most blocking
            first; empty when no neighbour is to blame (e.g. no face pair fits the jaws).
        reason: when not `ok`, why in words ("'b' is above the object at the pick", "no
            top-down 2F-85 grasp clears the neighbours: …"); "" when `ok`.
        grasps: feasible grasps found (at most the `limit` asked for; not ranked).
    """

    ok: bool
    blockers: tuple[str, ...] = ()  # most blocking first
    reason: str = ""
    grasps: tuple[Grasp, ...] = ()


@dataclass(frozen=True, kw_only=True)
class Infeasible:
    """The first step of an order that the robot cannot make."""

    step: int
    object: str
    verdict: MoveVerdict

    def __str__(self) -> str:
        return f"step {self.step} ({self.object}): {self.verdict.reason}"


class MoveCheck:
    """Whether the robot can make single moves — a grasp that clears the neighbours at the pick
    and at the place, and nothing above the object at either (it rises straight up and comes
    straight down) — cached on the poses involved.

    Args:
        meshes: mesh key → mesh (object frame).
        symmetries: mesh key → (n, 4, 4) object-frame symmetry transforms.
        pieces: mesh key → convex pieces (object frame), for the vertical sweep.
        margins: clearances tried between the gripper and the neighbours [m].
    """

    def __init__(
        self,
        meshes: Mapping[str, trimesh.Trimesh],
        symmetries: Mapping[str, np.ndarray],
        pieces: Mapping[str, Sequence[Piece]],
        *,
        margins: tuple[float, ...] = TOLERANCES.grasp_margins,
    ) -> None:
        self.meshes = meshes
        self.symmetries = symmetries
        self.parts = pieces
        self.margins = margins
        self._cache: dict[Any, MoveVerdict] = {}
        self._sweeps: dict[Any, Body] = {}
        self._xy: dict[str, np.ndarray] = {
            k: np.asarray(m.vertices)[:, :2] for k, m in meshes.items()
        }

    def move(
        self,
        oid: str,
        mesh: str,
        T_from: np.ndarray,
        T_to: np.ndarray,
        others: Mapping[str, tuple[str, np.ndarray]],
        place_others: Mapping[str, tuple[str, np.ndarray]] | None = None,
        *,
        limit: int = 1,
    ) -> MoveVerdict:
        """Can `oid` be moved from `T_from` to `T_to` with `others` ({id: (mesh, pose)})
        around the pick and `place_others` (default: the same) around the place? Collects up
        to `limit` feasible grasps (their reachability is the arm's IK, outside this model)."""
        place_others = others if place_others is None else place_others
        pick = self._near(T_from, mesh, others, oid)
        place = self._near(T_to, mesh, place_others, oid)
        key = (oid, mesh, _pose_key(T_from), _pose_key(T_to), pick, place, limit)
        if key not in self._cache:
            self._cache[key] = self._plan(oid, mesh, T_from, T_to, others, place_others, key)
        return self._cache[key]

    def pickable(
        self, oid: str, mesh: str, T: np.ndarray, others: Mapping[str, tuple[str, np.ndarray]]
    ) -> MoveVerdict:
        """Can `oid` be picked (and put back) where it is, among `others`?"""
        return self.move(oid, mesh, T, T, others, others)

    def first_infeasible(
        self, start: Sequence[Mapping], steps: Sequence[Mapping]
    ) -> Infeasible | None:
        """The first step of `steps` from the records `start` the robot cannot make, or None."""
        state = {r["id"]: (r["mesh"], np.asarray(r["pose"], float)) for r in start}
        for k, step in enumerate(steps):
            oid = step["object"]
            mesh, pose = state[oid]
            others = {j: v for j, v in state.items() if j != oid}
            target = np.asarray(step["target_pose"], float)
            verdict = self.move(oid, mesh, pose, target, others)
            if not verdict.ok:
                return Infeasible(step=k, object=oid, verdict=verdict)
            state[oid] = (mesh, target)
        return None

    # -- internals ---------------------------------------------------------------------------

    def _near(
        self, T: np.ndarray, mesh: str, others: Mapping[str, tuple[str, np.ndarray]], oid: str
    ) -> tuple:
        """The neighbours that could be in the gripper's way (a cache key: ids and poses)."""
        centre = self._xy[mesh] @ T[:2, :2].T + T[:2, 3]
        lo, hi = centre.min(axis=0) - NEAR, centre.max(axis=0) + NEAR
        out = []
        for j in sorted(others):
            if j == oid:
                continue
            m, pose = others[j]
            xy = self._xy[m] @ pose[:2, :2].T + pose[:2, 3]
            if np.all(xy.max(axis=0) >= lo) and np.all(xy.min(axis=0) <= hi):
                out.append((j, m, _pose_key(pose)))
        return tuple(out)

    def _above(self, mesh: str, T: np.ndarray, near: tuple, pool: Mapping) -> list[str]:
        """Neighbours in the vertical sweep of the object's convex parts above pose `T`."""
        touch, clear = TOLERANCES.sweep_touch, TOLERANCES.sweep_clearance
        lo, hi = self._box(mesh, T)
        swept: Body | None = None
        out = []
        for j, m, _ in near:
            lo_j, hi_j = self._box(m, pool[j][1])
            # a neighbour wholly over the object (an overhang) must clear its sweep: the object
            # passes under its edge; one beside it may touch the sweep (it stands next to it)
            need = clear if lo_j[2] >= hi[2] else -touch
            reach = max(need, touch)
            # a neighbour beside the object's outline, or wholly below it, is not above it
            if np.any(lo_j[:2] > hi[:2] + reach) or np.any(hi_j[:2] < lo[:2] - reach):
                continue
            if hi_j[2] < lo[2]:
                continue
            if swept is None:
                swept = self._sweep(mesh, T)
            body = place(j, self.parts[m], pool[j][1])
            if body_separation(swept, body, cutoff=reach)[0] < need:
                out.append(j)
        return out

    def _box(self, mesh: str, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World axis-aligned bounds (lo, hi) of the mesh at `T`."""
        v = np.asarray(self.meshes[mesh].vertices) @ T[:3, :3].T + T[:3, 3]
        return v.min(axis=0), v.max(axis=0)

    def _sweep(self, mesh: str, T: np.ndarray) -> Body:
        """The object's convex parts at `T` swept straight up (cached on the pose)."""
        key = (mesh, _pose_key(T))
        got = self._sweeps.get(key)
        if got is None:
            pieces = []
            for p in place("", self.parts[mesh], T).pieces:
                v = p.vertices
                pieces.append(Piece.of(np.vstack([v, v + UP])))
            got = self._sweeps[key] = Body(id="", pieces=tuple(pieces))
        return got

    def _plan(self, oid, mesh, T_from, T_to, others, place_others, key) -> MoveVerdict:
        for where, T, near, pool in (
            ("pick", T_from, key[4], others),
            ("place", T_to, key[5], place_others),
        ):
            above = self._above(mesh, T, near, pool)
            if above:
                return MoveVerdict(
                    ok=False,
                    blockers=tuple(above),
                    reason=f"{above[0]!r} is above the object at the {where}",
                )

        def obstacles(near, pool):
            return [Obstacle(id=j, mesh=self.meshes[m], pose=pool[j][1]) for j, m, _ in near]

        report = plan_grasps(
            self.meshes[mesh],
            T_from,
            T_to,
            symmetries=list(self.symmetries[mesh]),
            pick_obstacles=obstacles(key[4], others),
            place_obstacles=obstacles(key[5], place_others),
            margins=self.margins,
            limit=key[6],
        )
        if report.grasps:
            return MoveVerdict(ok=True, grasps=report.grasps)
        blockers = tuple(sorted(report.blockers, key=lambda j: -report.blockers[j]))
        return MoveVerdict(
            ok=False,
            blockers=blockers,
            reason=f"no top-down 2F-85 grasp clears the neighbours: {report.summary()}",
        )


def _pose_key(T: np.ndarray) -> bytes:
    return np.round(np.asarray(T, float)[:3], 7).tobytes()
