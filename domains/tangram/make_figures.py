"""Solve every tangram silhouette and write `figures.json`: `python -m domains.tangram.make_figures`."""

from __future__ import annotations

import sys

import numpy as np

from domains.benchmark import dumps
from domains.tangram.figures import HERE, SILHOUETTES, solve


def main() -> int:
    out = {}
    for name, polys in SILHOUETTES.items():
        tiling = solve(polys)
        if tiling is None:
            print(f"{name}: no tiling with the seven pieces", file=sys.stderr)
            return 1
        allp = np.concatenate([np.asarray(p, float) for p in polys])
        centre = (allp.min(axis=0) + allp.max(axis=0)) / 2
        out[name] = {
            "silhouette": [[list(map(float, v)) for v in p] for p in polys],
            "centre": [float(v) for v in centre],
            "pieces": {i: {"rotation_45": k, "centroid": c} for i, (k, c) in tiling.items()},
        }
        print(f"{name}: tiled")
    (HERE / "figures.json").write_text(dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
