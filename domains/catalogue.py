"""A domain's catalogue as data: its objects, meshes, cameras and scoring tolerance.

Design rule: plain frozen values read from the domain's folder (`catalogue.json`,
`cameras.json`, `tolerances.json`); nothing here computes geometry.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


@dataclass(frozen=True, kw_only=True)
class ObjectSpec:
    """One object instance of the catalogue."""

    id: str
    mesh: str  # key into the domain's meshes
    colour: tuple[float, float, float, float]  # RGBA in [0, 1]
    mass: float  # [kg]
    friction: float  # sliding friction coefficient


@dataclass(frozen=True, kw_only=True)
class MeshSpec:
    """A mesh of the catalogue; `frame` says in words where its canonical frame is."""

    key: str
    file: Path  # watertight OBJ, metres, in the canonical frame
    collision: tuple[Path, ...]  # convex parts whose union is the mesh
    symmetry: Mapping[str, Any]  # see `domains.symmetry`
    frame: str


@dataclass(frozen=True, kw_only=True)
class CameraSpec:
    """A pinhole camera looking from `position` at `target` [m], square pixels, centred."""

    name: str
    width: int
    height: int
    fovy: float  # vertical field of view [deg]
    position: tuple[float, float, float]
    target: tuple[float, float, float]

    def to_camera(self) -> dict:
        """The camera in the DESIGN format: K (3, 3) and T_world_camera (4, 4), OpenCV axes."""
        p, t = np.array(self.position, float), np.array(self.target, float)
        forward = (t - p) / np.linalg.norm(t - p)
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        pose = np.eye(4)
        pose[:3, :3] = np.stack([right, down, forward], axis=1)
        pose[:3, 3] = p
        f = (self.height / 2) / np.tan(np.radians(self.fovy) / 2)
        k = np.array(
            [[f, 0.0, (self.width - 1) / 2], [0.0, f, (self.height - 1) / 2], [0.0, 0.0, 1.0]]
        )
        return {"width": self.width, "height": self.height, "K": k, "T_world_camera": pose}


@dataclass(frozen=True, kw_only=True)
class Tolerance:
    """Scoring tolerance: an object is right when within both bounds, modulo symmetry."""

    translation: float  # [m]
    rotation: float | None  # [rad]; None: orientation is not scored (e.g. cubes)
