"""The camera envelope: the cameras a domain's programs must work with, beyond its named views.

A generated `perceive` takes the camera as a parameter; the checks hold it to that by drawing
cameras from an envelope around the domain's three named views (`cameras.json`). A camera of
the envelope looks at a point near the named views' common target, from

- an azimuth about the vertical through that point (0 = from +x, the side facing the robot),
- an elevation above the table,
- a distance,
- a vertical field of view, a roll about the optical axis,
- an image size from a short list (16:9 and 4:3),

each drawn uniformly within bounds that reach past the named views on every side
(`CameraEnvelope.around`). A draw is kept only when every point it must show projects inside
the image with a margin (`CameraEnvelope.draw(..., shows=points)`), so that a camera never
leaves an object out of the frame: objects hide each other, never the frame's edge.

Cameras are plain camera dicts (`{"width", "height", "K", "T_world_camera"}`, OpenCV axes,
square pixels, the principal point at the image centre), the format of `docs/cameras/*.json`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

SIZES: tuple[tuple[int, int], ...] = ((1280, 720), (960, 540), (1024, 768), (1280, 960))
MARGIN = 0.04  # a shown point stays this fraction of the image size inside its edges
MAX_TRIES = 200  # draws before `draw` gives up on showing every point


def look_at(position: Any, target: Any, *, roll: float = 0.0) -> np.ndarray:
    """T_world_camera (4, 4) of a camera at `position` looking at `target`, image x level with
    the table, turned by `roll` [rad] about its optical axis (OpenCV axes)."""
    p, t = np.asarray(position, float), np.asarray(target, float)
    forward = (t - p) / np.linalg.norm(t - p)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    c, s = math.cos(roll), math.sin(roll)
    right, down = c * right + s * down, -s * right + c * down
    pose = np.eye(4)
    pose[:3, :3] = np.stack([right, down, forward], axis=1)
    pose[:3, 3] = p
    return pose


def pinhole(width: int, height: int, fovy_deg: float) -> np.ndarray:
    """K (3, 3): square pixels, principal point at the image centre."""
    f = (height / 2) / math.tan(math.radians(fovy_deg) / 2)
    return np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])


def scaled(camera: dict, scale: int) -> dict:
    """`camera` at 1/`scale` of its resolution: the same view and field of view."""
    w, h = int(camera["width"]) // scale, int(camera["height"]) // scale
    k = np.asarray(camera["K"], float)
    fovy = 2 * math.degrees(math.atan((int(camera["height"]) / 2) / k[1, 1]))
    return {
        "width": w,
        "height": h,
        "K": pinhole(w, h, fovy),
        "T_world_camera": np.array(camera["T_world_camera"], float),
    }


def resized(camera: dict, factor: float) -> dict:
    """`camera` with its width and height times `factor` (rounded to even pixels): the same
    view and field of view, finer or coarser pixels."""
    h0 = int(camera["height"])
    fovy = 2 * math.degrees(math.atan((h0 / 2) / float(np.asarray(camera["K"])[1, 1])))
    w = 2 * max(1, round(int(camera["width"]) * factor / 2))
    h = 2 * max(1, round(h0 * factor / 2))
    return {
        "width": w,
        "height": h,
        "K": pinhole(w, h, fovy),
        "T_world_camera": np.array(camera["T_world_camera"], float),
    }


def project(camera: dict, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(pixels (N, 2), depth along the optical axis (N,)) of world `points` (N, 3)."""
    t = np.asarray(camera["T_world_camera"], float)
    local = (np.asarray(points, float) - t[:3, 3]) @ t[:3, :3]
    z = local[:, 2]
    uv = (np.asarray(camera["K"], float) @ local.T).T
    return uv[:, :2] / np.where(np.abs(uv[:, 2:]) < 1e-12, 1e-12, uv[:, 2:]), z


def shows(camera: dict, points: np.ndarray, margin: float = MARGIN) -> bool:
    """Whether every one of `points` (N, 3) is in front of the camera and inside the image,
    `margin` of its width and height away from the edges."""
    if len(points) == 0:
        return True
    uv, z = project(camera, points)
    w, h = int(camera["width"]), int(camera["height"])
    return bool(
        (z > 0.05).all()
        and (uv[:, 0] >= margin * w).all()
        and (uv[:, 0] <= (1 - margin) * w - 1).all()
        and (uv[:, 1] >= margin * h).all()
        and (uv[:, 1] <= (1 - margin) * h - 1).all()
    )


@dataclass(frozen=True, kw_only=True)
class CameraEnvelope:
    """Bounds of the cameras a domain's programs must handle (see the module docstring).

    Angles in degrees, lengths in metres.
    """

    target: tuple[float, float, float]  # the point the envelope's cameras look near
    target_jitter: float  # each of x, y of the looked-at point within ± this of `target`
    azimuth: tuple[float, float]
    elevation: tuple[float, float]
    distance: tuple[float, float]
    fovy: tuple[float, float]
    roll: float  # within ± this
    sizes: tuple[tuple[int, int], ...] = SIZES

    @staticmethod
    def around(views: Iterable[Any]) -> CameraEnvelope:
        """The envelope of named views (`domains.CameraSpec`s): 20° of azimuth past the outermost views on
        each side, 10° of elevation below the lowest and above the highest, 10 % nearer than
        the nearest and 25 % farther than the farthest, 6° narrower and 10° wider fields of
        view, 4° of roll, the looked-at point within 4 cm."""
        views = list(views)
        target = np.mean([v.target for v in views], axis=0)
        az, el, dist = [], [], []
        for v in views:
            d = np.asarray(v.position, float) - target
            az.append(math.degrees(math.atan2(d[1], d[0])))
            el.append(math.degrees(math.atan2(d[2], math.hypot(d[0], d[1]))))
            dist.append(float(np.linalg.norm(d)))
        fov = [v.fovy for v in views]
        return CameraEnvelope(
            target=(round(float(target[0]), 4), round(float(target[1]), 4), float(target[2])),
            target_jitter=0.04,
            azimuth=(round(min(az) - 20, 1), round(max(az) + 20, 1)),
            elevation=(round(min(el) - 10, 1), round(min(max(el) + 10, 80.0), 1)),
            distance=(round(0.9 * min(dist), 3), round(1.25 * max(dist), 3)),
            fovy=(min(fov) - 6, max(fov) + 10),
            roll=4.0,
        )

    def camera(
        self,
        *,
        azimuth: float,
        elevation: float,
        distance: float,
        fovy: float,
        roll: float = 0.0,
        size: tuple[int, int] = SIZES[0],
        target: Any = None,
    ) -> dict:
        """The camera with these parameters (degrees, metres)."""
        t = np.asarray(self.target if target is None else target, float)
        a, e = math.radians(azimuth), math.radians(elevation)
        p = t + distance * np.array(
            [math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)]
        )
        w, h = size
        return {
            "width": int(w),
            "height": int(h),
            "K": pinhole(w, h, fovy),
            "T_world_camera": look_at(p, t, roll=math.radians(roll)),
        }

    def draw(self, rng: np.random.Generator, *, shows_points: np.ndarray | None = None) -> dict:
        """A camera drawn uniformly from the envelope; with `shows_points` (N, 3), one that
        shows all of them (`shows`), redrawn up to `MAX_TRIES` times. Raises ValueError when
        no draw shows them."""
        for _ in range(MAX_TRIES):
            target = np.array(self.target, float)
            target[:2] += rng.uniform(-self.target_jitter, self.target_jitter, 2)
            cam = self.camera(
                azimuth=float(rng.uniform(*self.azimuth)),
                elevation=float(rng.uniform(*self.elevation)),
                distance=float(rng.uniform(*self.distance)),
                fovy=float(rng.uniform(*self.fovy)),
                roll=float(rng.uniform(-self.roll, self.roll)),
                size=self.sizes[int(rng.integers(len(self.sizes)))],
                target=target,
            )
            if shows_points is None or shows(cam, shows_points):
                return cam
        raise ValueError(
            f"no camera of the envelope shows all {0 if shows_points is None else len(shows_points)} points"
        )

    @property
    def description(self) -> str:
        """The envelope in one paragraph (for docs, prompts and reports)."""
        sizes = ", ".join(f"{w}×{h}" for w, h in self.sizes)
        x, y, z = self.target
        return (
            f"cameras looking at a point within {self.target_jitter * 100:g} cm (in x and y) of "
            f"({x:g}, {y:g}, {z:g}) m, from azimuth {self.azimuth[0]:g}° to {self.azimuth[1]:g}° "
            f"about the vertical (0° = from +x, facing the robot), elevation {self.elevation[0]:g}° "
            f"to {self.elevation[1]:g}° above the table, {self.distance[0]:g} to "
            f"{self.distance[1]:g} m away, vertical field of view {self.fovy[0]:g}° to "
            f"{self.fovy[1]:g}°, roll within ±{self.roll:g}°, image sizes {sizes}; every object "
            f"of the scene inside the frame"
        )
