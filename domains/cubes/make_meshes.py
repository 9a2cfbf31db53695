"""Write the cubes domain's meshes: `python -m domains.cubes.make_meshes`.

cube: a 40 mm cube. Canonical frame: origin at the cube's centre, axes along its edges.
"""

from __future__ import annotations

from pathlib import Path

import trimesh

from domains import _meshing

SIDE = 0.04  # [m]
HERE = Path(__file__).parent


def build() -> dict[str, trimesh.Trimesh]:
    return {"cube": trimesh.creation.box((SIDE, SIDE, SIDE))}


def main() -> None:
    for key, mesh in build().items():
        _meshing.export(mesh, HERE / "meshes" / f"{key}.obj")


if __name__ == "__main__":
    main()
