"""Observation folders (DESIGN, BOP-style): what `rivet solve` reads and `rivet scene render`
writes.

Design rule: numpy and OpenCV only — the thin runtime reads observations without the
simulator. A folder holds `rgb.png` (8-bit RGB), `depth.png` (16-bit, millimetres ×
1/`depth_scale`, i.e. depth [mm] = value × depth_scale, as in BOP) and `camera.json` (the
camera plus `depth_scale`; default 0.1, so 0.1 mm steps up to 6.5 m).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from artifacts.errors import ObservationError
from contracts import to_jsonable, validate
from contracts.errors import ContractError

DEPTH_SCALE = 0.1  # depth.png units: value × depth_scale = millimetres


def write_observation(
    obs: Mapping, folder: str | Path, *, depth_scale: float = DEPTH_SCALE
) -> Path:
    """Write rgb.png, depth.png and camera.json into `folder` (created)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rgb = np.asarray(obs["rgb"], np.uint8)
    depth_mm = np.asarray(obs["depth"], np.float64) * 1000.0
    units = np.round(depth_mm / depth_scale)
    units[(units < 0) | (units > 65535)] = 0
    if not cv2.imwrite(str(folder / "rgb.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        raise ObservationError(f"cannot write {folder / 'rgb.png'}")
    cv2.imwrite(str(folder / "depth.png"), units.astype(np.uint16))
    cam = {**to_jsonable(dict(obs["camera"])), "depth_scale": depth_scale}
    validate("observation", cam)
    (folder / "camera.json").write_text(json.dumps(cam, indent=1) + "\n")
    return folder


def read_observation(folder: str | Path) -> dict[str, Any]:
    """Read an observation folder: {"rgb", "depth" [m], "camera"}.

    Raises:
        ObservationError (a UsageError: exit code 2): a missing or unreadable file, or a
            `camera.json` that is not a valid observation camera (the contract's message,
            after the file's name).
    """
    folder = Path(folder)
    for name in ("rgb.png", "depth.png", "camera.json"):
        if not (folder / name).is_file():
            raise ObservationError(f"{folder}: not an observation folder (no {name})")
    try:
        cam = json.loads((folder / "camera.json").read_text())
    except json.JSONDecodeError as e:
        raise ObservationError(f"{folder / 'camera.json'}: not JSON ({e.msg})") from None
    try:  # the user's folder (`rivet solve`): an invalid camera is bad input (exit code 2)
        validate("observation", cam)
    except ContractError as e:
        raise ObservationError(f"{folder / 'camera.json'}: {e}") from None
    bgr = cv2.imread(str(folder / "rgb.png"), cv2.IMREAD_COLOR)
    raw = cv2.imread(str(folder / "depth.png"), cv2.IMREAD_UNCHANGED)
    if bgr is None or raw is None or raw.dtype != np.uint16:
        raise ObservationError(f"{folder}: rgb.png must be 8-bit colour and depth.png 16-bit")
    if raw.shape != (cam["height"], cam["width"]) or bgr.shape[:2] != raw.shape:
        raise ObservationError(
            f"{folder}: image sizes do not match camera.json ({cam['width']}×{cam['height']})"
        )
    depth = (raw.astype(np.float64) * cam["depth_scale"] / 1000.0).astype(np.float32)
    camera = {
        "width": cam["width"],
        "height": cam["height"],
        "K": np.asarray(cam["K"], float),
        "T_world_camera": np.asarray(cam["T_world_camera"], float),
    }
    return {"rgb": cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), "depth": depth, "camera": camera}
