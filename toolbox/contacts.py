"""Physical plausibility from poses and meshes: collisions, resting-on relations, placement.

Design rule: geometric tests on posed meshes, no simulation: points sampled densely on each
surface (vertices, edges, faces) are tested against the other object's signed distance, in
both directions, so meshes must be closed (watertight). The table is the plane z = `table_height` (default 0, DESIGN.md).
Records are `{"id", "mesh", "pose"}` with `pose` = `T_world_object` (4, 4) [m].
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import cv2
import numpy as np

from toolbox._surface import posed, signed_distance, surface_samples
from toolbox.errors import ToolboxError
from toolbox.geometry import make_pose, rotation_about_axis

__all__ = [
    "poses_collide",
    "resting_pose",
    "support_relations",
    "unsupported_objects",
    "world_bounds",
]

TABLE = "table"


def world_bounds(mesh, pose: object) -> np.ndarray:
    """Axis-aligned world bounds (2, 3) [m] — rows (min xyz, max xyz) — of a posed mesh."""
    V = posed(np.asarray(mesh.vertices, dtype=float), np.asarray(pose, dtype=float))
    return np.stack([V.min(axis=0), V.max(axis=0)])


def poses_collide(
    records: Sequence[Mapping],
    meshes: Mapping[str, object],
    *,
    tolerance: float = 0.001,
    table_height: float | None = 0.0,
) -> list[tuple[str, str, float]]:
    """Pairs of objects that interpenetrate by more than `tolerance` [m].

    Touching (stacked, side by side) is not a collision. With `table_height` set, an object
    reaching more than `tolerance` below the table collides with "table".

    Returns:
        [(id_a, id_b, depth [m]), ...] with ids in record order; empty when collision-free.
        Depth is approximate (resolution of the surface sampling, ~1/50 of object size).

    Raises:
        ToolboxError: a record names an unknown mesh or has a bad pose.
    """
    items = _items(records, meshes)
    boxes = [world_bounds(m, T) for _, m, T in items]
    out = []
    for i in range(len(items)):
        if table_height is not None and boxes[i][0, 2] < table_height - tolerance:
            out.append((items[i][0], TABLE, float(table_height - boxes[i][0, 2])))
        for j in range(i + 1, len(items)):
            if np.any(boxes[i][0] > boxes[j][1] + tolerance) or np.any(
                boxes[j][0] > boxes[i][1] + tolerance
            ):
                continue
            depth = max(_penetration(items[i], items[j]), _penetration(items[j], items[i]))
            if depth > tolerance:
                out.append((items[i][0], items[j][0], depth))
    return out


def support_relations(
    records: Sequence[Mapping],
    meshes: Mapping[str, object],
    *,
    tolerance: float = 0.002,
    table_height: float | None = 0.0,
) -> list[tuple[str, str]]:
    """Which object rests on which: (upper_id, lower_id) pairs, lower_id "table" for the table.

    A rests on B when a downward-facing part of A's surface lies within `tolerance` [m] of an
    upward-facing part of B's surface (normals within ~45° of -z and +z), i.e. A's bottom
    touches B's top; A rests on the table when its lowest point is within `tolerance` of it.
    Side contacts are not support. An object can rest on several others.
    """
    items = _items(records, meshes)
    return [(a, b) for a, b, _ in _contacts(items, tolerance, table_height)]


def unsupported_objects(
    records: Sequence[Mapping],
    meshes: Mapping[str, object],
    *,
    tolerance: float = 0.002,
    table_height: float | None = 0.0,
) -> list[str]:
    """Ids of objects that would fall: touching nothing below them, or with their centre of
    mass (mesh centroid) outside the convex hull of their support contacts, seen from above.

    Returns ids in record order; empty when every object is statically supported.
    """
    items = _items(records, meshes)
    contacts: dict[str, list[np.ndarray]] = {rid: [] for rid, _, _ in items}
    for upper, _, pts in _contacts(items, tolerance, table_height):
        contacts[upper].append(pts)
    out = []
    for rid, mesh, T in items:
        if not contacts[rid]:
            out.append(rid)
            continue
        pts = np.vstack(contacts[rid])[:, :2].astype(np.float32)
        com = posed(np.asarray(_centroid(mesh))[None], T)[0, :2]
        hull = cv2.convexHull(pts)
        inside = cv2.pointPolygonTest(hull, (float(com[0]), float(com[1])), True)
        if inside < -tolerance:
            out.append(rid)
    return out


def resting_pose(
    mesh,
    x: float,
    y: float,
    yaw: float = 0.0,
    *,
    rotation: object = None,
    height: float = 0.0,
) -> np.ndarray:
    """Pose `T_world_object` (4, 4) placing the mesh with its lowest point at z = `height` [m].

    Args:
        mesh: trimesh.Trimesh in its object frame.
        x, y: world position [m] of the object frame's origin.
        yaw: rotation [rad] about world z, applied after `rotation`.
        rotation: optional (3, 3) base orientation (e.g. lying on its side); default identity.
        height: support height [m]: 0 for the table, or the top of the object below
            (`world_bounds(mesh_b, pose_b)[1, 2]` for a flat top).
    """
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
    if R.shape != (3, 3):
        raise ToolboxError(f"rotation must be (3, 3), got {R.shape}")
    R = rotation_about_axis((0, 0, 1), yaw) @ R
    z_min = float((np.asarray(mesh.vertices, dtype=float) @ R.T)[:, 2].min())
    return make_pose(R, [x, y, height - z_min])


def _items(
    records: Sequence[Mapping], meshes: Mapping[str, object]
) -> list[tuple[str, object, np.ndarray]]:
    out = []
    for i, r in enumerate(records):
        key = r.get("mesh") if isinstance(r, Mapping) else None
        if key is None or key not in meshes:
            known = ", ".join(sorted(map(str, meshes))) or "(none)"
            raise ToolboxError(f"records[{i}].mesh {key!r} is not a known mesh; known: {known}")
        T = np.asarray(r.get("pose"), dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ToolboxError(f"records[{i}].pose must be a finite (4, 4) matrix")
        out.append((str(r.get("id", i)), meshes[key], T))
    return out


def _penetration(a, b) -> float:
    """How deep [m] samples of object a reach inside object b (0 when none do)."""
    _, mesh_a, T_a = a
    _, mesh_b, T_b = b
    pts_b = posed(surface_samples(mesh_a)[0], np.linalg.inv(T_b) @ T_a)  # a's samples in b's frame
    sd, _ = signed_distance(mesh_b, pts_b)
    return float(max(0.0, -sd.min()))


def _contacts(items, tolerance: float, table_height: float | None):
    """(upper_id, lower_id, contact points (k, 3) world) for every support contact."""
    out = []
    for i, (rid, mesh, T) in enumerate(items):
        samples, normals_a = surface_samples(mesh)
        world = posed(samples, T)
        down = (normals_a @ T[:3, :3].T)[:, 2] < -0.7  # False for NaN (edge/vertex samples)
        if table_height is not None:
            on_table = world[:, 2] < table_height + tolerance
            if on_table.any():
                out.append((rid, TABLE, world[on_table]))
        lo, hi = world.min(axis=0), world.max(axis=0)
        for j, (rid_b, mesh_b, T_b) in enumerate(items):
            if i == j:
                continue
            box = world_bounds(mesh_b, T_b)
            if np.any(lo > box[1] + tolerance) or np.any(box[0] > hi + tolerance):
                continue
            sd, normals = signed_distance(mesh_b, posed(samples, np.linalg.inv(T_b) @ T))
            up = normals @ T_b[:3, :3].T  # b's surface normals in the world
            touch = down & (np.abs(sd) < tolerance) & (up[:, 2] > 0.7)
            if touch.any():
                out.append((rid, rid_b, world[touch]))
    return out


def _centroid(mesh) -> np.ndarray:
    if mesh.is_watertight and mesh.volume > 0:
        return np.asarray(mesh.center_mass, dtype=float)
    return np.asarray(mesh.bounds, dtype=float).mean(axis=0)
