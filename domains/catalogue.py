"""A domain's catalogue as data: its objects, meshes, cameras and scoring tolerance.

Design rule: plain frozen values read from the domain's folder (`catalogue.json`,
`cameras.json`, `tolerances.json`); nothing here computes geometry.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from domains.cameras import look_at, pinhole


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
        return {
            "width": self.width,
            "height": self.height,
            "K": pinhole(self.width, self.height, self.fovy),
            "T_world_camera": look_at(self.position, self.target),
        }


@dataclass(frozen=True, kw_only=True)
class Tolerance:
    """Scoring tolerance: an object is right when within both bounds, modulo symmetry."""

    translation: float  # [m]
    rotation: float | None  # [rad]; None: orientation is not scored (e.g. cubes)
