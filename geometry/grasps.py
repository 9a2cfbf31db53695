"""Top-down parallel-jaw grasps, from an object's mesh, its pose and its target — the one grasp
model the executor, the plan checks, the generators' construction planner and the programs
(through `toolbox.hand`) all use.

Design rule: a grasp is chosen once per transfer and held rigidly from pick to place, so it is
planned in the object's frame and checked at both ends. Candidates come from pairs of
antiparallel mesh faces that are vertical at the pick pose and no more than the jaws' stroke
apart; each pair gives two wrist yaws (the gripper is symmetric under a half turn) and the
object's symmetries give several equivalent place poses. A candidate is kept when the fingers,
opened for the approach, clear the object itself, the table and every neighbour at the pick
and at the place (`geometry.clearance`). Reachability (the wrist's joint limits) is decided by
the caller's IK. The gripper is `geometry.robot.ROBOT`'s; no simulator is needed here.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trimesh

from contracts import se3
from geometry.clearance import Triangles, first_hit, gripper_hits, world_triangles
from geometry.robot import ROBOT, FingerModel, GripperStroke
from geometry.tolerances import TOLERANCES

VERTICAL_TOL = TOLERANCES.face_vertical
ANTIPARALLEL_TOL = TOLERANCES.face_antiparallel
YAW_ONLY_TOL = TOLERANCES.yaw_only


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
    key = (id(mesh), pose_key(T_pick), max_width, fingers, id(table))
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
    obj_tris = world_triangles(mesh, T_pick)
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
    max_width: float | None = None,
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
        fingers: the gripper's boxes; None: `ROBOT.gripper.fingers`.
        max_width: widest face pair the jaws take [m]; None: `ROBOT.gripper.max_grasp_width`.
        margins: clearances tried against neighbours [m], larger (preferred) first.
        max_symmetries: per face pair and wrist yaw, how many place options (fewest wrist
            rotation first) are checked.
        limit: stop once this many grasps are found (a feasibility test: the grasps returned
            are then not necessarily the best). None: all.
    """
    gripper = ROBOT.gripper
    fingers = fingers or gripper.fingers
    max_width = gripper.max_grasp_width if max_width is None else max_width
    table = gripper.stroke
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
    own_pick = Triangles.of(mesh, T_pick)
    pick_sets = [Triangles.of(o.mesh, o.pose) for o in pick_obstacles]
    place_sets = [Triangles.of(o.mesh, o.pose) for o in place_obstacles]
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
                cache[key] = first_hit(tcp, gap, reach, margin, pick_sets, fingers)
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
                        own_hit[key] = gripper_hits(
                            tcp_pick, pair.width + 0.002, reach, 0.0, [own_pick], fingers
                        ) or gripper_hits(tcp_pick, open_gap, reach, 0.0, [own_pick], fingers)
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
    place_sets: Sequence[Triangles],
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
        index = first_hit(tcp_place, gap, reach, margin, place_sets, fingers)
        if index >= 0:
            hit = ("place", index)
            continue
        return float(margin), hit
    return None, hit


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


def pose_key(T: np.ndarray) -> bytes:
    """A pose as a cache key (rounded to 0.1 µm)."""
    return np.round(np.asarray(T, float)[:3], 7).tobytes()


__all__ = ["Grasp", "GraspReport", "Obstacle", "plan_grasps", "pose_key"]
