"""The MuJoCo world: scenes, settling, RGB-D observations, scoring (and the robot executor).

Headless default: when neither `MUJOCO_GL` nor a `DISPLAY` is set, rendering uses EGL
(`MUJOCO_GL=egl`, `PYOPENGL_PLATFORM=egl`); this must happen before MuJoCo is imported, so
import `sim` before `mujoco` when you render.
"""

from __future__ import annotations

import os

if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from sim.errors import InvalidCameraError, InvalidSceneError, SimError
from sim.observation import (
    DepthNoise,
    contact_sheet,
    observe,
)
from sim.scene import build_spec, load_instance, parse_instance, parse_scene
from sim.score import final_success, object_errors, state_accuracy
from sim.settle import check_order, check_scene, validate_scene

__all__ = [
    "DepthNoise",
    "InvalidCameraError",
    "InvalidSceneError",
    "SimError",
    "build_spec",
    "check_order",
    "check_scene",
    "contact_sheet",
    "final_success",
    "load_instance",
    "object_errors",
    "observe",
    "parse_instance",
    "parse_scene",
    "state_accuracy",
    "validate_scene",
]
