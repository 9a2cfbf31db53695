"""Instances: a start scene, a goal scene and a construction order — and their JSON form.

There is one `Instance` in the project (the generators make it, the benchmark files hold it,
trials and checks read it); scenes inside it are DESIGN scene specs with poses as arrays.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True, kw_only=True)
class Instance:
    """A start scene, a goal scene and a construction order from one to the other."""

    domain: str
    name: str
    seed: int | None
    start: dict
    goal: dict
    order: tuple[dict, ...] = field(default=())  # plan steps {"object", "target_pose"}

    def to_dict(self) -> dict:
        """JSON-ready form (poses as nested lists)."""
        return {
            "domain": self.domain,
            "name": self.name,
            "seed": self.seed,
            "start": scene_to_json(self.start),
            "goal": scene_to_json(self.goal),
            "order": {
                "status": "ok",
                "steps": [
                    {"object": s["object"], "target_pose": _pose_json(s["target_pose"])}
                    for s in self.order
                ],
            },
        }

    @staticmethod
    def from_dict(value: Mapping[str, Any]) -> Instance:
        """Read the JSON form; `order`, `name` and `seed` are optional."""
        steps = (value.get("order") or {}).get("steps", [])
        return Instance(
            domain=value["domain"],
            name=value.get("name", ""),
            seed=value.get("seed"),
            start=scene_from_json(value["start"]),
            goal=scene_from_json(value["goal"]),
            order=tuple(
                {"object": s["object"], "target_pose": np.asarray(s["target_pose"], float)}
                for s in steps
            ),
        )


def _pose_json(pose: Any) -> list[list[float]]:
    return [[round(float(v), 10) + 0.0 for v in row] for row in np.asarray(pose, float)]


def scene_to_json(scene: Mapping[str, Any]) -> dict:
    """A scene with poses as nested lists (rounded to 1e-10)."""
    return {
        "domain": scene["domain"],
        "objects": [
            {"id": o["id"], "mesh": o["mesh"], "pose": _pose_json(o["pose"])}
            for o in scene["objects"]
        ],
    }


def scene_from_json(scene: Mapping[str, Any]) -> dict:
    """A scene with poses as (4, 4) float arrays (no validation: see `sim.scene.parse_scene`)."""
    return {
        "domain": scene["domain"],
        "objects": [
            {"id": o["id"], "mesh": o["mesh"], "pose": np.asarray(o["pose"], float)}
            for o in scene["objects"]
        ],
    }
