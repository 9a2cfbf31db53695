"""Deterministic ICP, RANSAC and Kabsch in numpy/scipy (private to registration).

Open3D's ICP and RANSAC reduce in parallel threads, so repeated calls differ in the last bits
(and RANSAC in its answer); generated programs must be deterministic, so the iterative parts
live here, single-threaded, with an explicit seed.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def kabsch(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Rigid transform (4, 4) minimising Σ w |T src - dst|² for paired points (n, 3)."""
    w = np.ones(len(src)) if weights is None else weights
    w = w / w.sum()
    cs, cd = w @ src, w @ dst
    H = (src - cs).T @ ((dst - cd) * w[:, None])
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    R = Vt.T @ D @ U.T
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, cd - R @ cs
    return T


def batch_kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Kabsch for a batch of point triples: src, dst (b, k, 3) → (b, 4, 4)."""
    cs, cd = src.mean(axis=1, keepdims=True), dst.mean(axis=1, keepdims=True)
    H = np.einsum("bki,bkj->bij", src - cs, dst - cd)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("bji,bkj->bik", Vt, U)))  # det(V Uᵀ)
    d[d == 0] = 1.0
    Vt = Vt * np.stack([np.ones_like(d), np.ones_like(d), d], axis=1)[:, :, None]
    R = np.einsum("bji,bkj->bik", Vt, U)  # V D Uᵀ
    T = np.tile(np.eye(4), (len(src), 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = cd[:, 0] - np.einsum("bij,bj->bi", R, cs[:, 0])
    return T


def estimate_normals(points: np.ndarray, tree: cKDTree, k: int = 16) -> np.ndarray:
    """Unoriented unit normals (n, 3) by PCA over the k nearest neighbours."""
    _, idx = tree.query(points, k=min(k, len(points)))
    nb = points[idx] - points[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    return np.linalg.eigh(cov)[1][:, :, 0]


def icp(
    src: np.ndarray,
    dst: np.ndarray,
    T0: np.ndarray,
    max_distance: float,
    iterations: int,
    *,
    tree: cKDTree | None = None,
    normals: np.ndarray | None = None,
) -> tuple[np.ndarray, float, float]:
    """(transform, fitness, rmse) of src onto dst; point-to-plane when dst `normals` are given."""
    tree = tree or cKDTree(dst)
    T = np.asarray(T0, dtype=float).copy()
    prev = np.inf
    for _ in range(int(iterations)):
        moved = src @ T[:3, :3].T + T[:3, 3]
        dist, idx = tree.query(moved, distance_upper_bound=max_distance)
        ok = np.isfinite(dist)
        if np.count_nonzero(ok) < 3:
            break
        if normals is None:
            step = kabsch(moved[ok], dst[idx[ok]])
        else:
            step = _point_to_plane_step(moved[ok], dst[idx[ok]], normals[idx[ok]])
        T = step @ T
        err = float(np.sqrt(np.mean(dist[ok] ** 2)))
        if abs(prev - err) < 1e-9 and np.allclose(step, np.eye(4), atol=1e-9):
            break
        prev = err
    fitness, rmse = score(src, T, tree, max_distance)
    return T, fitness, rmse


def score(
    src: np.ndarray, T: np.ndarray, tree: cKDTree, max_distance: float
) -> tuple[float, float]:
    """(fraction of src within max_distance of the tree's points after T, inlier rmse)."""
    dist, _ = tree.query(src @ T[:3, :3].T + T[:3, 3], distance_upper_bound=max_distance)
    ok = np.isfinite(dist)
    if not ok.any():
        return 0.0, float("inf")
    return float(np.count_nonzero(ok) / len(src)), float(np.sqrt(np.mean(dist[ok] ** 2)))


def ransac(
    src: np.ndarray,
    dst: np.ndarray,
    pairs: np.ndarray,
    max_distance: float,
    *,
    seed: int,
    iterations: int = 20000,
    batch: int = 1000,
) -> np.ndarray:
    """Best transform (4, 4) from correspondence pairs (m, 2) of src/dst indices (3-point RANSAC
    with an edge-length consistency check); identity when fewer than 3 pairs."""
    if len(pairs) < 3:
        return np.eye(4)
    rng = np.random.default_rng(seed)
    a, b = src[pairs[:, 0]], dst[pairs[:, 1]]
    best_T, best_count = np.eye(4), -1
    done = 0
    while done < iterations:
        done += batch
        pick = rng.integers(0, len(pairs), size=(batch, 3))
        pick = pick[
            (pick[:, 0] != pick[:, 1]) & (pick[:, 1] != pick[:, 2]) & (pick[:, 0] != pick[:, 2])
        ]
        sa, sb = a[pick], b[pick]  # (batch, 3, 3)
        la = np.linalg.norm(sa - np.roll(sa, 1, axis=1), axis=2)
        lb = np.linalg.norm(sb - np.roll(sb, 1, axis=1), axis=2)
        ratio = np.minimum(la, lb) / np.maximum(np.maximum(la, lb), 1e-12)
        good = np.all(ratio > 0.9, axis=1) & np.all(la > max_distance, axis=1)
        if not good.any():
            continue
        Ts = batch_kabsch(sa[good], sb[good])
        moved = Ts[:, :3, :3] @ a.T + Ts[:, :3, 3:]  # (b, 3, m)
        sq = np.sum((moved - b.T) ** 2, axis=1)
        counts = np.count_nonzero(sq < max_distance**2, axis=1)
        i = int(np.argmax(counts))
        if counts[i] > best_count:
            best_T, best_count = Ts[i], int(counts[i])
            # Adaptive stop: enough samples to draw one all-inlier triple with p = 0.999.
            w = best_count / len(pairs)
            if w >= 1.0:
                break
            iterations = min(iterations, int(np.ceil(np.log(1e-3) / np.log(1.0 - w**3))))
    inliers = np.linalg.norm(a @ best_T[:3, :3].T + best_T[:3, 3] - b, axis=1) < max_distance
    return kabsch(a[inliers], b[inliers]) if np.count_nonzero(inliers) >= 3 else best_T


def match_features(fs: np.ndarray, ft: np.ndarray) -> np.ndarray:
    """Pairs (m, 2) of nearest neighbours in feature space (rows are points), mutual when at
    least 30 mutual pairs exist."""
    fwd = cKDTree(ft).query(fs)[1]
    back = cKDTree(fs).query(ft)[1]
    pairs = np.stack([np.arange(len(fs)), fwd], axis=1)
    mutual = pairs[back[fwd] == np.arange(len(fs))]
    return mutual if len(mutual) >= 30 else pairs


def _point_to_plane_step(p: np.ndarray, q: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Linearised point-to-plane update (small rotation + translation), re-orthonormalised."""
    A = np.hstack([np.cross(p, n), n])  # (k, 6)
    r = np.einsum("ij,ij->i", q - p, n)
    x, *_ = np.linalg.lstsq(A, r, rcond=None)
    w, t = x[:3], x[3:]
    theta = np.linalg.norm(w)
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if theta < 1e-12:
        R = np.eye(3)
    else:
        K = K / theta
        R = np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * (K @ K)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T
