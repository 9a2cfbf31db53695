"""Input checks shared by the toolbox modules (private)."""

from __future__ import annotations

import numpy as np

from toolbox.errors import ToolboxError


def camera_matrices(camera: dict) -> tuple[np.ndarray, np.ndarray]:
    """(K (3, 3), T_world_camera (4, 4)) from a camera dict, checked."""
    if not isinstance(camera, dict):
        raise ToolboxError(f"camera must be a dict, got {type(camera).__name__}")
    missing = [k for k in ("width", "height", "K", "T_world_camera") if k not in camera]
    if missing:
        raise ToolboxError(f"camera is missing {', '.join(missing)}")
    K = np.asarray(camera["K"], dtype=float)
    T = np.asarray(camera["T_world_camera"], dtype=float)
    if K.shape != (3, 3) or T.shape != (4, 4):
        raise ToolboxError(
            f"camera K must be (3, 3) and T_world_camera (4, 4), got {K.shape}, {T.shape}"
        )
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(T))) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ToolboxError("camera K must be finite with positive focal lengths")
    return K, T


def camera_size(camera: dict) -> tuple[int, int]:
    """(width, height) in pixels, checked."""
    w, h = int(camera["width"]), int(camera["height"])
    if w <= 0 or h <= 0:
        raise ToolboxError(f"camera size must be positive, got {w}x{h}")
    return w, h


def check_image(image: object, camera: dict | None, name: str, *, ndim: int) -> np.ndarray:
    """An array with `ndim` dims whose (H, W) match the camera when given."""
    a = np.asarray(image)
    if a.ndim != ndim:
        raise ToolboxError(f"{name} must have {ndim} dimensions, got shape {a.shape}")
    if camera is not None:
        w, h = camera_size(camera)
        if a.shape[:2] != (h, w):
            raise ToolboxError(f"{name} has shape {a.shape[:2]} but the camera is {h}x{w} (HxW)")
    return a


def check_points(points: object, name: str) -> np.ndarray:
    """A float (N, 3) array."""
    P = np.asarray(points, dtype=float)
    if P.ndim == 1 and P.size == 0:
        return P.reshape(0, 3)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ToolboxError(f"{name} must have shape (N, 3), got {P.shape}")
    return P


def rng_from(seed: int | None) -> np.random.Generator:
    return np.random.default_rng(seed)
