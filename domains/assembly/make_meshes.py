"""Write the assembly domain's meshes and catalogue: `python -m domains.assembly.make_meshes`.

Seven wooden parts, 30–160 mm, each graspable from above across a 30–40 mm face pair.
Canonical frame of every part: origin at the centre of the bottom face of its bounding box
in its upright resting pose, x along its length, y across (the gripper's usual jaw
direction), z up. The arch, roof and L-block are profiles in x–z extruded along y; the arch's
opening is a half-disc on a short rectangle, approximated by a 16-sided arc (the convex
parts slice the material above it into quadrilaterals, so their union is the mesh exactly).
"""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import trimesh

from domains import _meshing
from domains.assembly.dimensions import (
    ARC_SEGMENTS,
    ARCH_H,
    ARCH_R,
    ARCH_SPRING,
    ARCH_W,
    BEAM,
    BLOCK,
    CYL_H,
    CYL_R,
    DEPTH,
    L_FOOT,
    L_LEG,
    PILLAR,
    ROOF_H,
    ROOF_W,
)

HERE = Path(__file__).parent
DENSITY = 600.0  # wood [kg/m³]


def _box(sx: float, sy: float, sz: float, x: float = 0.0, z: float = 0.0) -> trimesh.Trimesh:
    """A box whose bottom face is centred at (x, 0, z)."""
    m = trimesh.creation.box((sx, sy, sz))
    m.apply_translation((x, 0, z + sz / 2))
    return m


def _profile(poly_xz: np.ndarray) -> trimesh.Trimesh:
    """Extrude a CCW x–z profile by DEPTH along y, centred on y = 0."""
    p = np.asarray(poly_xz, float)
    if _meshing.polygon_area(p) < 0:
        p = p[::-1]
    m = _meshing.prism(p, -DEPTH / 2, DEPTH / 2)  # extruded along z for now
    rot = np.eye(4)
    rot[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # (a, b, c) → (a, -c, b)
    m.apply_transform(rot)
    return m


def _arc() -> np.ndarray:
    t = np.linspace(np.pi, 0.0, ARC_SEGMENTS + 1)
    return np.c_[ARCH_R * np.cos(t), ARCH_SPRING + ARCH_R * np.sin(t)]


def arch() -> tuple[trimesh.Trimesh, list[trimesh.Trimesh]]:
    w, h = ARCH_W / 2, ARCH_H
    outline = [
        (-w, 0.0),
        (-ARCH_R, 0.0),
        *map(tuple, _arc()),
        (ARCH_R, 0.0),
        (w, 0.0),
        (w, h),
        (-w, h),
    ]
    mesh = _profile(np.array(outline))
    parts = [_profile(np.array([(-w, 0), (-ARCH_R, 0), (-ARCH_R, h), (-w, h)]))]
    arc = _arc()
    for a, b in itertools.pairwise(arc):
        parts.append(_profile(np.array([a, b, (b[0], h), (a[0], h)])))
    parts.append(_profile(np.array([(ARCH_R, 0), (w, 0), (w, h), (ARCH_R, h)])))
    return mesh, parts


def lblock() -> tuple[trimesh.Trimesh, list[trimesh.Trimesh]]:
    (fl, fh), (lw, lh) = L_FOOT, L_LEG
    x0 = -fl / 2
    outline = [(x0, 0), (-x0, 0), (-x0, fh), (x0 + lw, fh), (x0 + lw, fh + lh), (x0, fh + lh)]
    foot = _profile(np.array([(x0, 0), (-x0, 0), (-x0, fh), (x0, fh)]))
    leg = _profile(np.array([(x0, fh), (x0 + lw, fh), (x0 + lw, fh + lh), (x0, fh + lh)]))
    return _profile(np.array(outline)), [foot, leg]


def build() -> dict[str, tuple[trimesh.Trimesh, list[trimesh.Trimesh]]]:
    pillar = _box(*PILLAR)
    beam = _box(*BEAM)
    block = _box(*BLOCK)
    roof = _profile(np.array([(-ROOF_W / 2, 0), (ROOF_W / 2, 0), (0, ROOF_H)]))
    cyl = trimesh.creation.cylinder(radius=CYL_R, height=CYL_H, sections=48)
    cyl.apply_translation((0, 0, CYL_H / 2))
    return {
        "pillar": (pillar, [pillar]),
        "beam": (beam, [beam]),
        "arch": arch(),
        "roof": (roof, [roof]),
        "cylinder": (cyl, [cyl]),
        "lblock": lblock(),
        "block": (block, [block]),
    }


SYMMETRY = {
    "pillar": {"kind": "dihedral", "n": 4, "axis": "z", "centre": [0, 0, PILLAR[2] / 2]},
    "beam": {"kind": "dihedral", "n": 2, "axis": "z", "centre": [0, 0, BEAM[2] / 2]},
    "arch": {"kind": "cyclic", "n": 2, "axis": "z"},
    "roof": {"kind": "cyclic", "n": 2, "axis": "z"},
    "cylinder": {
        "kind": "revolution",
        "axis": "z",
        "flip": True,
        "steps": 360,
        "centre": [0, 0, CYL_H / 2],
    },
    "lblock": {"kind": "identity"},
    "block": {"kind": "dihedral", "n": 2, "axis": "z", "centre": [0, 0, BLOCK[2] / 2]},
}
FRAMES = {
    "pillar": "30×30×80 mm square pillar standing; origin at the centre of its bottom face",
    "beam": "160×35×20 mm beam lying flat; origin at the centre of its bottom face, x along it",
    "arch": (
        "120×35×65 mm arch standing, a 60 mm half-round opening underneath (springline 20 mm); "
        "origin at the centre of its bottom face, x across the opening"
    ),
    "roof": "140 mm wide, 40 mm tall, 35 mm deep triangular wedge on its base; origin at the base's centre, x along the base",
    "cylinder": "Ø40×60 mm cylinder standing; origin at the centre of its bottom face",
    "lblock": (
        "L-block: an 80×35×30 mm foot with a 30×35×40 mm leg on its -x end (70 mm tall); "
        "origin at the centre of the foot's bottom face, x along the foot"
    ),
    "block": "50×35×30 mm block lying flat; origin at the centre of its bottom face, x along it",
}
OBJECTS = {
    "pillar_1": ("pillar", [0.80, 0.18, 0.14, 1.0]),
    "pillar_2": ("pillar", [0.97, 0.56, 0.10, 1.0]),
    "beam": ("beam", [0.15, 0.34, 0.85, 1.0]),
    "arch": ("arch", [0.95, 0.82, 0.12, 1.0]),
    "roof": ("roof", [0.15, 0.60, 0.24, 1.0]),
    "cylinder": ("cylinder", [0.56, 0.26, 0.76, 1.0]),
    "lblock": ("lblock", [0.10, 0.74, 0.80, 1.0]),
    "block": ("block", [0.96, 0.46, 0.66, 1.0]),
}


def main() -> None:
    meshes, volumes = {}, {}
    for key, (mesh, parts) in build().items():
        _meshing.export(mesh, HERE / "meshes" / f"{key}.obj")
        files = []
        for j, p in enumerate(parts if len(parts) > 1 else []):
            f = f"meshes/{key}_part{j}.obj"
            _meshing.export(p, HERE / f)
            files.append(f)
        meshes[key] = {
            "file": f"meshes/{key}.obj",
            "collision": files or [f"meshes/{key}.obj"],
            "symmetry": SYMMETRY[key],
            "frame": FRAMES[key],
        }
        volumes[key] = float(mesh.volume)
    objects = [
        {
            "id": oid,
            "mesh": key,
            "colour": colour,
            "mass": round(DENSITY * volumes[key], 4),
            "friction": 0.7,
        }
        for oid, (key, colour) in OBJECTS.items()
    ]
    (HERE / "catalogue.json").write_text(
        json.dumps({"meshes": meshes, "objects": objects}, indent=1) + "\n"
    )


if __name__ == "__main__":
    main()
