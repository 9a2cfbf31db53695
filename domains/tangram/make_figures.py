"""Solve every tangram silhouette and write `figures.json` (the dev split's figures) and
`test_figures.json` (the test split's): `python -m domains.tangram.make_figures`."""

from __future__ import annotations

import sys
from collections.abc import Mapping

import numpy as np

from domains.benchmark import dumps
from domains.tangram.figures import HERE, SILHOUETTES, TEST_FAMILIES, TEST_SILHOUETTES, solve


def tile(silhouettes: Mapping[str, list], family: Mapping[str, str] | None = None) -> dict | None:
    out = {}
    for name, polys in silhouettes.items():
        tiling = solve(polys)
        if tiling is None:
            print(f"{name}: no tiling with the seven pieces", file=sys.stderr)
            return None
        allp = np.concatenate([np.asarray(p, float) for p in polys])
        centre = (allp.min(axis=0) + allp.max(axis=0)) / 2
        out[name] = {
            "silhouette": [[list(map(float, v)) for v in p] for p in polys],
            "centre": [float(v) for v in centre],
            "pieces": {i: {"rotation_45": k, "centroid": c} for i, (k, c) in tiling.items()},
        }
        if family is not None:
            out[name]["family"] = family[name]
        print(f"{name}: tiled")
    return out


def main() -> int:
    dev = tile(SILHOUETTES)
    family = {n: f for f, names in TEST_FAMILIES.items() for n in names}
    test = tile(TEST_SILHOUETTES, family)
    if dev is None or test is None:
        return 1
    (HERE / "figures.json").write_text(dumps(dev))
    (HERE / "test_figures.json").write_text(dumps(test))
    return 0


if __name__ == "__main__":
    sys.exit(main())
