"""Draw camera files from the domains' camera envelope (`domains.cameras`).

    python scripts/draw_cameras.py --count 5 --seed 2026 --out docs/cameras

A drawn camera is kept only when it shows every object of every benchmark instance (both
splits, start and goal) of every domain inside its frame, so that one file serves
`rivet eval D --camera FILE` in any domain. Files are named `envelope-K.json` and hold
`{width, height, K, T_world_camera}`; the lines printed (size, position, field of view) go
into docs/cameras/README.md.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

import domains
from checks.inputs import _corners, records
from domains.cameras import shows


def benchmark_points() -> np.ndarray:
    pts = []
    for name in domains.names():
        dom = domains.load(name)
        for split in ("dev", "test"):
            for inst in dom.benchmark(split):
                for scene in (inst.start, inst.goal):
                    pts.append(_corners(dom, records(scene)))
    return np.concatenate(pts)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--count", type=int, default=5)
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument("--out", type=Path, default=Path("docs/cameras"))
    args = p.parse_args()
    envelopes = {domains.load(n).camera_envelope for n in domains.names()}
    if len(envelopes) != 1:
        raise SystemExit("the domains' envelopes differ: draw per domain")
    (envelope,) = envelopes
    points = benchmark_points()
    rng = np.random.default_rng(args.seed)
    args.out.mkdir(parents=True, exist_ok=True)
    for k in range(1, args.count + 1):
        cam = envelope.draw(rng, shows_points=points)
        t = cam["T_world_camera"]
        fovy = 2 * math.degrees(math.atan((cam["height"] / 2) / cam["K"][1, 1]))
        doc = {
            "width": cam["width"],
            "height": cam["height"],
            "K": np.round(cam["K"], 6).tolist(),
            "T_world_camera": np.round(t, 9).tolist(),
        }
        assert shows(cam, points)
        path = args.out / f"envelope-{k}.json"
        path.write_text(json.dumps(doc, indent=2) + "\n")
        x, y, z = np.round(t[:3, 3], 3)
        print(f"| `{path.name}` | {cam['width']}×{cam['height']} | ({x}, {y}, {z}) | {fovy:.1f}° |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
