"""The workspace promise, object by object: every object (one per mesh; objects sharing a mesh
are the same) alone on the table, anywhere in the domain's workspace (every vertex inside it) at four yaws — does one of the executor's grasp
candidates (`geometry.grasps` through `Domain.grasps`) have an arm solution
(`sim.reach.Reach`, the executor's IK) at the pick and the place (here the same pose)?

Usage:
    python -m benchmarks.reach_sweep [--domain assembly] [--step 0.05]
Prints every pose without a reachable grasp and the totals; exit 1 when there is one.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

import numpy as np

import domains
from geometry import yaw_pose
from sim.reach import Reach

YAWS_DEG = (0.0, 45.0, 90.0, 135.0)


def sweep(name: str, step: float) -> tuple[int, list[str]]:
    """(poses tried, the poses without a reachable grasp, described)."""
    domain = domains.load(name)
    reach, ws = Reach(), domain.workspace
    tried, bad, seen = 0, [], set()
    for obj in domain.objects:
        if obj.mesh in seen:
            continue
        seen.add(obj.mesh)
        mesh = domain.mesh(obj.mesh)
        z0 = -float(mesh.vertices[:, 2].min())
        for x in np.arange(ws.x[0], ws.x[1] + 1e-9, step):
            for y in np.arange(ws.y[0], ws.y[1] + 1e-9, step):
                for yaw in YAWS_DEG:
                    T = yaw_pose(x, y, z0, np.radians(yaw))
                    if ws.outside(mesh.vertices @ T[:3, :3].T + T[:3, 3]) is not None:
                        continue
                    tried += 1
                    verdict = domain.grasps.move(obj.id, obj.mesh, T, T, {}, limit=8)
                    got = reach.any(verdict.grasps) if verdict.ok else None
                    if got is None or not got.ok:
                        why = got.reason if got is not None else "no grasp"
                        bad.append(f"{obj.mesh} at ({x:.3f}, {y:.3f}), yaw {yaw:.0f}°: {why}")
                        print(bad[-1], file=sys.stderr, flush=True)
    return tried, bad


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default="assembly", choices=domains.names())
    ap.add_argument("--step", type=float, default=0.05, help="grid step [m]")
    args = ap.parse_args(argv)
    tried, bad = sweep(args.domain, args.step)
    print(f"{args.domain}: {len(bad)} of {tried} poses without a reachable grasp")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
