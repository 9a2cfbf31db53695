"""`toolbox.refine_poses` from perturbed poses: how often it lands within tolerance, how fast.

For each domain, draws dev instances (`Domain.generate(seed)`), observes their start and goal
scenes (`sim.observation.observe`, default realism unless told), perturbs every object's pose
and refines the perturbed records with automatic colour segments, their hue peaks matched to
the objects by the input poses (`--segments auto`) or by the catalogue colours (`colors`), or
with the simulator's object masks (`truth`: tells segmentation failures from search ones). The start is the true pose
(`--start truth`) or what the people-written `perceive` of the domain reports
(`--start reference`). The refiner gets the camera levelled on the table
(`level_camera_on_table`), as the domains' perceive programs use it. The
perturbation: x and y uniform in ±`--shift`, z in ±`--shift`/3, a turn about the vertical
through the object's centre uniform in ±`--yaw` degrees, plus a quarter turn with
probability `--swap` (a box fitted with its length for its width). An object converges when
it ends within the domain's scoring tolerance (`sim.score.object_errors`), modulo symmetry.
Objects with no segment (not seen) keep their pose and are counted apart. Times are per
`refine_poses` call, CPU (`time.process_time`) and wall clock.

Usage:
    python -m benchmarks.refine_bench [--domain D ...] [--scenes 10] [--seed 0]
        [--camera front] [--realism default] [--start truth|reference] [--shift 0.015]
        [--yaw 30] [--swap 0.3] [--dof planar] [--json OUT]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import domains

DOMAINS = domains.names()


def perturb(records: list[dict], meshes: dict, rng: np.random.Generator, args) -> list[dict]:
    """The records moved and turned as the module docstring says."""
    out = []
    for r in records:
        T = np.array(r["pose"], dtype=float)
        centre = T[:3, :3] @ meshes[r["mesh"]].bounds.mean(axis=0) + T[:3, 3]
        yaw = np.radians(rng.uniform(-args.yaw, args.yaw))
        if rng.random() < args.swap:
            yaw += np.pi / 2
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        P = T.copy()
        P[:3, :3] = R @ T[:3, :3]
        P[:3, 3] = R @ (T[:3, 3] - centre) + centre
        P[:3, 3] += rng.uniform(-1, 1, 3) * np.array([1.0, 1.0, 1 / 3]) * args.shift
        out.append({"id": r["id"], "mesh": r["mesh"], "pose": P})
    return out


def load_perceive(domain: str):
    path = Path(domains.__file__).parent / domain / "programs" / "perceive.py"
    spec = importlib.util.spec_from_file_location(f"_reference_perceive_{domain}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.perceive


def run_domain(name: str, args) -> dict[str, Any]:
    from sim.observation import load_camera, observe
    from sim.score import object_errors
    from toolbox import level_camera_on_table, refine_poses

    domain = domains.load(name)
    meshes = domain.meshes()
    camera = args.camera
    if camera not in domain.cameras:
        camera = load_camera(camera)
    perceive = load_perceive(name) if args.start == "reference" else None
    rows, cpu, wall = [], [], []
    for k in range(args.scenes):
        seed = args.seed + k
        instance = domain.generate(seed)
        for side, scene in (("start", instance.start), ("goal", instance.goal)):
            obs = observe(
                domain,
                scene,
                camera,
                seed=seed,
                realism=args.realism,
                mask=args.segments == "truth",
            )
            segments = colors = None
            if args.segments == "truth":  # the simulator's object mask: the segmentation's limit
                segments = {r["id"]: obs["mask"] == k for k, r in enumerate(scene["objects"])}
            elif args.segments == "colors":  # the catalogue's colours, as a program knows them
                colors = {
                    i: 255 * np.asarray(domain.object(i).colour[:3]) for i in domain.object_ids
                }
            rng = np.random.default_rng([seed, side == "goal"])
            # the camera the domains' perceive programs use: levelled on the table
            cam = level_camera_on_table(obs["depth"], obs["camera"])
            if perceive is None:
                start = [dict(r) for r in scene["objects"]]
            else:
                start = perceive(obs, meshes, obs["camera"])
            rough = perturb(start, meshes, rng, args)
            t0, c0 = time.perf_counter(), time.process_time()
            fits = refine_poses(
                obs, meshes, rough, camera=cam, dof=args.dof, segments=segments, colors=colors
            )
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            truth = scene["objects"]
            before = {e.id: e for e in object_errors(domain, rough, truth)}
            after = {e.id: e for e in object_errors(domain, [f.record() for f in fits], truth)}
            for f in fits:
                if f.id not in after:
                    continue
                rows.append(
                    {
                        "scene": f"{instance.name}/{side}",
                        "id": f.id,
                        "seen": f.pixels > 0,
                        "good": f.good,
                        "within_before": bool(before[f.id].within),
                        "within": bool(after[f.id].within),
                        "error_mm": round(1000 * after[f.id].translation, 2),
                        "error_deg": round(float(np.degrees(after[f.id].rotation)), 2),
                        "iou": round(f.iou, 3),
                        "depth_residual_mm": round(1000 * f.depth_residual_m, 2),
                        "seen_through": round(f.seen_through, 3),
                        "hypothesis": f.hypothesis,
                    }
                )
    seen = [r for r in rows if r["seen"]]
    good = [r for r in seen if r["good"]]
    return {
        "domain": name,
        "observations": len(cpu),
        "objects": len(rows),
        "seen": len(seen),
        "within_before": sum(r["within_before"] for r in seen),
        "within": sum(r["within"] for r in seen),
        "rate_seen": round(sum(r["within"] for r in seen) / max(len(seen), 1), 4),
        "good": len(good),
        "within_when_good": sum(r["within"] for r in good),
        "missed_when_good": sum(not r["within"] for r in good),
        "cpu_s_median": round(float(np.median(cpu)), 3),
        "cpu_s_max": round(float(np.max(cpu)), 3),
        "wall_s_median": round(float(np.median(wall)), 3),
        "wall_s_max": round(float(np.max(wall)), 3),
        "iou_within": _quantiles([r["iou"] for r in seen if r["within"]]),
        "iou_not_within": _quantiles([r["iou"] for r in seen if not r["within"]]),
        "failures": [r for r in seen if not r["within"]],
        "rows": rows,
    }


def _quantiles(values: list[float]) -> list[float]:
    """Minimum, 5th, 50th percentile and maximum (empty: [])."""
    if not values:
        return []
    return [round(float(np.percentile(values, q)), 3) for q in (0, 5, 50, 100)]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--domain", action="append", choices=DOMAINS)
    p.add_argument("--scenes", type=int, default=10, help="instances per domain (start + goal)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--camera", default="front", help="a view name or a camera file")
    p.add_argument("--realism", default="default", choices=("clean", "default", "harsh"))
    p.add_argument("--start", default="truth", choices=("truth", "reference"))
    p.add_argument("--shift", type=float, default=0.015, help="[m]")
    p.add_argument("--yaw", type=float, default=30.0, help="[deg]")
    p.add_argument("--swap", type=float, default=0.3, help="probability of a quarter turn")
    p.add_argument("--dof", default="planar", choices=("planar", "full"))
    p.add_argument(
        "--segments",
        default="auto",
        choices=("auto", "colors", "truth"),
        help="colour segments matched by the input poses (auto) or by the catalogue colours "
        "(colors), or the simulator's object masks (truth)",
    )
    p.add_argument("--json", type=Path)
    args = p.parse_args(argv)
    if args.scenes < 1:
        p.error("--scenes must be >= 1")
    results = []
    for name in args.domain or DOMAINS:
        r = run_domain(name, args)
        results.append(r)
        print(
            f"{name}: {r['within']}/{r['seen']} seen objects within tolerance "
            f"({100 * r['rate_seen']:.1f} %; {r['within_before']} before), "
            f"{r['objects'] - r['seen']} not seen; good {r['good']} "
            f"(of them {r['missed_when_good']} not within); "
            f"CPU median {r['cpu_s_median']} s, max {r['cpu_s_max']} s; "
            f"wall median {r['wall_s_median']} s, max {r['wall_s_max']} s "
            f"({r['observations']} observations)"
        )
        for f in r["failures"]:
            print(
                f"   {f['scene']} {f['id']}: {f['error_mm']} mm {f['error_deg']} deg, "
                f"iou {f['iou']}, good {f['good']}, {f['hypothesis']}"
            )
    if args.json:
        args.json.write_text(
            json.dumps(
                {"args": vars(args) | {"json": str(args.json)}, "results": results}, indent=1
            )
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
