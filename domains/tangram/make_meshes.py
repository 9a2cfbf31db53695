"""Write the tangram domain's meshes and catalogue: `python -m domains.tangram.make_meshes`.

Seven pieces cut from a 160 mm square (lattice unit 40 mm), 15 mm thick, each carrying a
16 mm square knob, 20 mm tall, at its area centroid: the gripper takes the knob, since the
pieces of a figure touch. The knob sits at the centroid so it does not break the piece's
symmetry. Every outline is shrunk by 0.25 mm per edge, so pieces in a figure stand 0.5 mm
apart instead of touching exactly.

Canonical frame of every piece: origin at the area centroid of the bottom face, z up through
the knob; triangles have the hypotenuse along +x and the right angle toward +y, the square
its edges along x and y, the parallelogram its long edge along +x leaning toward +x (its
handedness is fixed: it cannot be turned over).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import trimesh

from domains import _meshing
from domains.tangram.figures import OBJECTS, UNIT, canonical

HERE = Path(__file__).parent
THICKNESS = 0.015  # [m]
KNOB_SIDE = 0.016  # [m]
KNOB_HEIGHT = 0.02  # [m]
CLEARANCE = 0.00025  # inward offset of every edge [m]
DENSITY = 700.0  # wood [kg/m³]
SYMMETRY = {
    "large_triangle": {"kind": "identity"},
    "medium_triangle": {"kind": "identity"},
    "small_triangle": {"kind": "identity"},
    "square": {"kind": "cyclic", "n": 4, "axis": "z"},
    "parallelogram": {"kind": "cyclic", "n": 2, "axis": "z"},
}
COLOURS = {
    "large_1": [0.85, 0.14, 0.14, 1.0],
    "large_2": [0.14, 0.33, 0.85, 1.0],
    "medium": [0.96, 0.80, 0.08, 1.0],
    "small_1": [0.14, 0.64, 0.24, 1.0],
    "small_2": [0.98, 0.50, 0.05, 1.0],
    "square": [0.56, 0.24, 0.76, 1.0],
    "parallelogram": [0.08, 0.76, 0.80, 1.0],
}


def outline(mesh: str) -> np.ndarray:
    """The piece's bottom outline [m], canonical frame, with the clearance applied."""
    return _meshing.offset_convex(canonical(mesh) * UNIT, CLEARANCE)


def build() -> dict[str, tuple[trimesh.Trimesh, list[trimesh.Trimesh]]]:
    """mesh key → (watertight mesh, convex parts)."""
    out = {}
    for key in dict.fromkeys(OBJECTS.values()):
        poly = outline(key)
        mesh = _meshing.prism_with_knob(poly, THICKNESS, np.zeros(2), KNOB_SIDE, KNOB_HEIGHT)
        h = KNOB_SIDE / 2
        knob = np.array([(-h, -h), (h, -h), (h, h), (-h, h)])
        parts = [
            _meshing.prism(poly, 0.0, THICKNESS),
            _meshing.prism(knob, THICKNESS, THICKNESS + KNOB_HEIGHT),
        ]
        out[key] = (mesh, parts)
    return out


def main() -> None:
    meshes: dict[str, dict] = {}
    volumes: dict[str, float] = {}
    for key, (mesh, parts) in build().items():
        _meshing.export(mesh, HERE / "meshes" / f"{key}.obj")
        files = []
        for j, p in enumerate(parts):
            f = f"meshes/{key}_part{j}.obj"
            _meshing.export(p, HERE / f)
            files.append(f)
        meshes[key] = {
            "file": f"meshes/{key}.obj",
            "collision": files,
            "symmetry": SYMMETRY[key],
            "frame": (
                "origin at the area centroid of the bottom face, z up through the knob; "
                + {
                    "square": "edges along x and y",
                    "parallelogram": "long edge along +x, leaning toward +x",
                }.get(key, "hypotenuse along +x, right angle toward +y")
            ),
        }
        volumes[key] = round(float(mesh.volume), 12)
    objects = [
        {
            "id": oid,
            "mesh": key,
            "colour": COLOURS[oid],
            "mass": round(DENSITY * volumes[key], 4),
            "friction": 0.6,
        }
        for oid, key in OBJECTS.items()
    ]
    (HERE / "catalogue.json").write_text(
        json.dumps({"meshes": meshes, "objects": objects}, indent=1) + "\n"
    )


if __name__ == "__main__":
    main()
