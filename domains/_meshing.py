"""Building watertight meshes from 2D profiles, for the domains' `make_meshes.py` scripts.

Only numpy and trimesh: profiles are simple polygons (counter-clockwise, metres) that are
extruded into prisms; a prism may carry a square knob on its top face, built as one closed
surface (not two touching solids) so the mesh stays a single watertight volume.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh


def polygon_area(poly: np.ndarray) -> float:
    """Signed area [m²] of a 2D polygon (positive when counter-clockwise)."""
    x, y = np.asarray(poly, float).T
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def offset_convex(poly: np.ndarray, d: float) -> np.ndarray:
    """Move every edge of a counter-clockwise convex polygon inwards by `d` [m]."""
    p = np.asarray(poly, float)
    n = len(p)
    lines = []
    for i in range(n):
        a, b = p[i], p[(i + 1) % n]
        t = (b - a) / np.linalg.norm(b - a)
        normal = np.array([-t[1], t[0]])  # inward for CCW
        lines.append((a + d * normal, t))
    out = []
    for i in range(n):
        (p0, t0), (p1, t1) = lines[i - 1], lines[i]
        m = np.array([t0, -t1]).T
        s = np.linalg.solve(m, p1 - p0)
        out.append(p0 + s[0] * t0)
    return np.array(out)


def triangulate(poly: np.ndarray) -> list[tuple[int, int, int]]:
    """Ear-clipping triangulation of a simple counter-clockwise polygon (index triples)."""
    p = np.asarray(poly, float)
    idx = list(range(len(p)))
    tris: list[tuple[int, int, int]] = []

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    def inside(q, a, b, c):
        return cross(a, b, q) >= -1e-15 and cross(b, c, q) >= -1e-15 and cross(c, a, q) >= -1e-15

    guard = 0
    while len(idx) > 3:
        guard += 1
        if guard > 10_000:
            raise ValueError("polygon is not simple or not counter-clockwise")
        for k in range(len(idx)):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            a, b, c = p[i0], p[i1], p[i2]
            if cross(a, b, c) <= 1e-15:
                continue
            if any(inside(p[j], a, b, c) for j in idx if j not in (i0, i1, i2)):
                continue
            tris.append((i0, i1, i2))
            idx.pop(k)
            break
        else:
            raise ValueError("no ear found: polygon is not simple or not counter-clockwise")
    tris.append((idx[0], idx[1], idx[2]))
    return tris


def _ring(outer: np.ndarray, inner: np.ndarray, centre: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangulate the ring between two CCW polygons, star-shaped about `centre`.

    Indices: outer vertices 0..n-1, inner vertices n..n+m-1.
    """
    n, m = len(outer), len(inner)

    def angles(p):
        return np.arctan2(p[:, 1] - centre[1], p[:, 0] - centre[0])

    ao, ai = angles(outer), angles(inner)
    o0 = int(np.argmin(ao))
    start = ao[o0]
    ai = (ai - start) % (2 * np.pi)
    i0 = int(np.argmin(ai))
    ao_seq = [(ao[(o0 + k) % n] - start) % (2 * np.pi) for k in range(n)] + [2 * np.pi]
    ai_seq = [ai[(i0 + k) % m] for k in range(m)] + [ai[i0] + 2 * np.pi]
    tris = []
    i = j = 0
    while i < n or j < m:
        take_outer = j >= m or (i < n and ao_seq[i + 1] <= ai_seq[j + 1])
        oi, oj = (o0 + i) % n, n + (i0 + j) % m
        if take_outer:
            tris.append((oi, (o0 + i + 1) % n, oj))
            i += 1
        else:
            tris.append((oj, oi, n + (i0 + j + 1) % m))
            j += 1
    return tris


def prism(poly: np.ndarray, z0: float, z1: float) -> trimesh.Trimesh:
    """Extrude a simple CCW polygon (k, 2) between heights z0 < z1 [m]."""
    p = np.asarray(poly, float)
    k = len(p)
    verts = np.concatenate([np.c_[p, np.full(k, z0)], np.c_[p, np.full(k, z1)]])
    tris = triangulate(p)
    faces = [(c, b, a) for a, b, c in tris]  # bottom, facing down
    faces += [(a + k, b + k, c + k) for a, b, c in tris]
    for i in range(k):
        j = (i + 1) % k
        faces += [(i, j, j + k), (i, j + k, i + k)]
    return _checked(trimesh.Trimesh(vertices=verts, faces=faces, process=True))


def prism_with_knob(
    poly: np.ndarray,
    thickness: float,
    knob_centre: np.ndarray,
    knob_side: float,
    knob_height: float,
) -> trimesh.Trimesh:
    """A convex CCW polygon extruded to `thickness` with a square knob on its top [m].

    The knob is axis-aligned in the polygon's frame and must lie inside the polygon.
    """
    p = np.asarray(poly, float)
    c = np.asarray(knob_centre, float)
    h = knob_side / 2
    sq = c + np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
    n, t, top = len(p), thickness, thickness + knob_height
    verts = np.concatenate(
        [
            np.c_[p, np.zeros(n)],
            np.c_[p, np.full(n, t)],
            np.c_[sq, np.full(4, t)],
            np.c_[sq, np.full(4, top)],
        ]
    )
    ob, ot, kb, kt = 0, n, 2 * n, 2 * n + 4
    faces = [(ob + c_, ob + b, ob + a) for a, b, c_ in triangulate(p)]
    for i in range(n):
        j = (i + 1) % n
        faces += [(ob + i, ob + j, ot + j), (ob + i, ot + j, ot + i)]
    for a, b, c_ in _ring(p, sq, c):
        va, vb, vc = (ot + v if v < n else kb + (v - n) for v in (a, b, c_))
        faces.append((va, vb, vc))
    for i in range(4):
        j = (i + 1) % 4
        faces += [(kb + i, kb + j, kt + j), (kb + i, kt + j, kt + i)]
    faces += [(kt + 0, kt + 1, kt + 2), (kt + 0, kt + 2, kt + 3)]
    mesh = trimesh.Trimesh(vertices=verts, faces=faces, process=True)
    expected = polygon_area(p) * t + knob_side**2 * knob_height
    if abs(mesh.volume - expected) > 1e-9:
        raise ValueError(f"knob prism volume {mesh.volume} != {expected}: bad ring triangulation")
    return _checked(mesh)


def _checked(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    if not (mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0):
        raise ValueError("mesh is not a closed, outward-facing volume")
    return mesh


def export(mesh: trimesh.Trimesh, path: Path) -> None:
    """Write `mesh` as a Wavefront OBJ with 9 decimals (stable, diff-friendly)."""
    lines = [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in np.asarray(mesh.vertices)]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.asarray(mesh.faces)]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def load(path: Path) -> trimesh.Trimesh:
    """Read an OBJ written by `export` (no merging or re-ordering of vertices)."""
    verts, faces = [], []
    for line in Path(path).read_text().splitlines():
        if line.startswith("v "):
            verts.append([float(v) for v in line.split()[1:4]])
        elif line.startswith("f "):
            faces.append([int(v.split("/")[0]) - 1 for v in line.split()[1:4]])
    return trimesh.Trimesh(vertices=np.array(verts), faces=np.array(faces), process=False)
