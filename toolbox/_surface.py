"""Cached surface samples and signed-distance queries of meshes (private to contacts)."""

from __future__ import annotations

import threading
from collections import OrderedDict

import numpy as np

_MAX_CACHED = 128
_LOCK = threading.Lock()
_SAMPLES: OrderedDict[tuple, tuple] = OrderedDict()
_SCENES: OrderedDict[tuple, tuple] = OrderedDict()


def posed(points: np.ndarray, T: np.ndarray) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    return np.asarray(points, dtype=float) @ T[:3, :3].T + T[:3, 3]


def surface_samples(mesh, n_faces: int = 2000, per_edge: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Object-frame samples (n, 3) and their outward normals (n, 3): vertices, points along
    sharp edges (normal NaN: ambiguous there), and area-uniform face points (deterministic).
    Edges matter: two boxes crossing edge to edge have no vertex inside each other."""
    key = (id(mesh), hash(mesh))

    def build():
        import trimesh

        V = np.asarray(mesh.vertices, dtype=float)
        parts = [V]
        normals = [np.full_like(V, np.nan)]
        edges = mesh.face_adjacency_edges[mesh.face_adjacency_angles > np.deg2rad(10)]
        if len(edges):
            edges = edges[: max(1, 4000 // per_edge)]
            t = np.linspace(0.0, 1.0, per_edge + 2)[1:-1]
            a, b = V[edges[:, 0]], V[edges[:, 1]]
            parts.append((a[:, None] + t[None, :, None] * (b - a)[:, None]).reshape(-1, 3))
            normals.append(np.full_like(parts[-1], np.nan))
        if len(mesh.faces):
            pts, face = trimesh.sample.sample_surface(mesh, n_faces, seed=0)
            parts.append(np.asarray(pts, dtype=float))
            normals.append(np.asarray(mesh.face_normals, dtype=float)[face])
        return np.vstack(parts), np.vstack(normals)

    return _cached(_SAMPLES, key, mesh, build)


def signed_distance(mesh, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(signed distance (n,) [m], negative inside; outward normal (n, 3) of the closest
    triangle) of object-frame points to the mesh surface."""
    import open3d as o3d

    key = (id(mesh), hash(mesh))

    def build():
        scene = o3d.t.geometry.RaycastingScene()
        tm = o3d.t.geometry.TriangleMesh()
        # Tensor(array) copies; from_numpy would alias a temporary.
        tm.vertex.positions = o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32))  # type: ignore[call-overload]
        tm.triangle.indices = o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.int32))  # type: ignore[call-overload]
        scene.add_triangles(tm)
        return (scene,)

    (scene,) = _cached(_SCENES, key, mesh, build)
    q = o3d.core.Tensor(np.asarray(points, dtype=np.float32))  # type: ignore[call-overload]
    sd = scene.compute_signed_distance(q).numpy().astype(float)
    normals = scene.compute_closest_points(q)["primitive_normals"].numpy().astype(float)
    return sd, normals


def _cached(cache: OrderedDict, key: tuple, mesh, build):
    with _LOCK:
        hit = cache.get(key)
        if hit is not None:
            cache.move_to_end(key)
            return hit[1]
    value = build()
    with _LOCK:
        cache[key] = (mesh, value)  # holding the mesh keeps its id from being reused
        while len(cache) > _MAX_CACHED:
            cache.popitem(last=False)
    return value
