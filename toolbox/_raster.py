"""A numpy triangle rasteriser for depth and object masks (private to refine).

`toolbox.render.render_scene` draws with OpenGL: exact, but its context costs ~0.5 s to open
and a call ~15 ms, too slow for the thousands of candidate poses a pose refiner
weighs. This draws the same thing on the CPU for small windows of a small image: a pixel is
covered when its centre (integer (u, v), the OpenCV convention render_scene also follows) lies
inside a triangle's projection, its depth is interpolated perspective-correctly (1/z is linear
in the image), and the nearest surface wins. tests/toolbox/test_refine.py holds its masks and
depths to render_scene's. Deterministic: no threads, no randomness.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ZNEAR = 0.05  # [m] triangles with a vertex nearer the camera are not drawn (as render_scene)


@dataclass(frozen=True, kw_only=True)
class Window:
    """A rectangle of the image: columns u0..u0+width-1, rows v0..v0+height-1."""

    u0: int
    v0: int
    width: int
    height: int


def rasterise(
    vertices: np.ndarray,
    faces: np.ndarray,
    K: np.ndarray,
    window: Window,
    *,
    cull: bool,
) -> np.ndarray:
    """Depth images (b, height, width) [m] of b posed copies of one mesh, inf where empty.

    Args:
        vertices: (b, n, 3) the mesh's vertices in the camera frame of each copy [m].
        faces: (f, 3) vertex indices.
        K: (3, 3) intrinsics of the image the window belongs to.
        window: the part of the image drawn.
        cull: drop triangles facing away from the camera (closed, consistently wound meshes).
    """
    b = len(vertices)
    h, w = window.height, window.width
    out = np.full(b * h * w, np.inf)
    tri = vertices[:, faces]  # (b, f, 3, 3)
    tri = tri.reshape(-1, 3, 3)
    owner = np.repeat(np.arange(b), len(faces))
    z = tri[:, :, 2]
    keep = np.all(z > ZNEAR, axis=1)
    if cull:
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        keep &= np.einsum("ij,ij->i", normal, tri[:, 0]) < 0
    tri, owner, z = tri[keep], owner[keep], z[keep]
    if len(tri) == 0:
        return out.reshape(b, h, w)
    x, y = tri[:, :, 0] / z, tri[:, :, 1] / z
    u = K[0, 0] * x + K[0, 1] * y + K[0, 2] - window.u0  # (t, 3) window pixels
    v = K[1, 1] * y + K[1, 2] - window.v0
    vmin = np.maximum(np.ceil(v.min(axis=1)), 0).astype(np.int64)
    vmax = np.minimum(np.floor(v.max(axis=1)), h - 1).astype(np.int64)
    # 1/z is affine in the image: 1/z = a u + b v + c over each triangle
    area = (u[:, 1] - u[:, 0]) * (v[:, 2] - v[:, 0]) - (u[:, 2] - u[:, 0]) * (v[:, 1] - v[:, 0])
    some = (vmax >= vmin) & (np.abs(area) > 1e-12) & (u.max(axis=1) >= 0) & (u.min(axis=1) <= w - 1)
    u, v, z, owner, vmin, vmax, area = (a[some] for a in (u, v, z, owner, vmin, vmax, area))
    if len(u) == 0:
        return out.reshape(b, h, w)
    q = 1.0 / z
    a = (
        (q[:, 1] - q[:, 0]) * (v[:, 2] - v[:, 0]) - (q[:, 2] - q[:, 0]) * (v[:, 1] - v[:, 0])
    ) / area
    bb = (
        (u[:, 1] - u[:, 0]) * (q[:, 2] - q[:, 0]) - (u[:, 2] - u[:, 0]) * (q[:, 1] - q[:, 0])
    ) / area
    c = q[:, 0] - a * u[:, 0] - bb * v[:, 0]
    # one span of pixel centres per (triangle, row): where the row crosses the triangle
    rows = vmax - vmin + 1
    t = np.repeat(np.arange(len(rows)), rows)
    y = (vmin[t] + np.arange(len(t)) - np.repeat(np.cumsum(rows) - rows, rows)).astype(float)
    left = np.full(len(t), np.inf)
    right = np.full(len(t), -np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):  # a horizontal edge's ends lie on the other two
        ui, vi, uj, vj = u[t, i], v[t, i], u[t, j], v[t, j]
        cross = (np.minimum(vi, vj) <= y) & (y <= np.maximum(vi, vj)) & (vi != vj)
        x = ui + (y - vi) * (uj - ui) / np.where(cross, vj - vi, 1.0)
        left = np.where(cross, np.minimum(left, x), left)
        right = np.where(cross, np.maximum(right, x), right)
    first = np.maximum(np.ceil(left - 1e-9), 0)
    last = np.minimum(np.floor(right + 1e-9), w - 1)
    count = np.maximum(last - first + 1, 0).astype(np.int64)
    total = int(count.sum())
    if total == 0:
        return out.reshape(b, h, w)
    r = np.repeat(np.arange(len(count)), count)  # the span of each covered pixel
    pu = first[r] + (np.arange(total) - np.repeat(np.cumsum(count) - count, count))
    tr = t[r]
    inv_z = a[tr] * pu + (bb[t] * y + c[t])[r]
    key = ((owner[t] * h + y.astype(np.int64)) * w)[r] + pu.astype(np.int64)
    np.minimum.at(out, key, 1.0 / inv_z)
    return out.reshape(b, h, w)
