"""`rivet scene …`: generate instances, render their observations, draw contact sheets.

    rivet scene generate DOMAIN --seed S --out INSTANCE.json
    rivet scene render INSTANCE.json --out DIR [--view V | --camera NAME|FILE.json]
                       [--realism clean|default|harsh] [--seed S] [--clean-depth] [--with-truth]
    rivet scene show INSTANCE.json --out SHEET.png [--camera NAME|FILE.json ...]
                     [--realism LEVEL ...] [--side start|goal|both] [--seed S]
                     [--tile-width W] [--crop X,Y,W,H] [--colors N]
    rivet scene benchmark DOMAIN [--split dev|test] [--check]

INSTANCE.json may also be a benchmark name such as ``cubes/goal01_start1`` (a test split
instance: ``cubes/test/goal01_start1``). Instances are
checked before use: malformed or physically invalid ones (interpenetrating, outside the
workspace, not at rest) are refused with exit code 2 and a message naming the object.

`render` writes the observation a robot would have: the image from the true camera, and in
camera.json the CALIBRATED camera (off by the realism level's calibration error; exact for
`clean`, the default). `--with-truth` adds true_camera.json (the true camera, in the camera
file format) to each folder. The start uses seed S, the goal S + 1; both share the
calibration of seed S (one camera, calibrated once). Camera files: docs/observations.md.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from contracts.errors import UsageError, user_input

LEVELS = ("clean", "default", "harsh")  # sim.realism.LEVELS (not imported: keeps --help fast)
VIEWS = ("front", "view1", "view2")


def _checked(arg: str):
    import sim  # noqa: F401  (sets the headless GL default before MuJoCo loads)
    from sim.scene import load_instance
    from sim.settle import validate_scene

    with user_input():  # the user's instance file: a malformed one exits 2
        domain, inst = load_instance(arg)
    validate_scene(domain, inst.start, where="start")
    validate_scene(domain, inst.goal, where="goal")
    return domain, inst


def generate(args: argparse.Namespace) -> int:
    import domains
    from domains.benchmark import dumps

    domain = domains.load(args.domain)
    from sim.settle import physical_problems

    inst = domain.generate(args.seed, physics=physical_problems, split=args.split)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(dumps(inst.to_dict()))
    print(
        f"{args.out}: {domain.name} {args.split} seed {args.seed}, "
        f"{len(inst.order)} construction steps"
    )
    return 0


def _camera(domain, value: str):
    """(label, camera) of a --camera/--view value: a view name of the domain or a camera file."""
    from sim.observation import load_camera

    if value in domain.cameras:
        return value, value
    path = Path(value)
    if not path.exists() and path.suffix != ".json" and "/" not in value:
        raise UsageError(
            f"--camera {value}: neither a view of {domain.name} ({', '.join(domain.cameras)}) "
            "nor a camera file"
        )
    return str(path), load_camera(path)


def render(args: argparse.Namespace) -> int:
    import json

    from artifacts.observations import write_observation
    from contracts import to_jsonable
    from sim.observation import observe_with_truth

    if args.view and args.camera:
        raise UsageError("give --view or --camera, not both")
    domain, inst = _checked(args.instance)
    label, camera = _camera(domain, args.view or args.camera or "front")
    depth: dict[str, Any] = {"noise": None} if args.clean_depth else {}
    for k, (side, scene) in enumerate((("start", inst.start), ("goal", inst.goal))):
        obs, truth = observe_with_truth(
            domain,
            scene,
            camera,
            seed=args.seed + k,
            calibration_seed=args.seed,
            realism=args.realism,
            **depth,
        )
        folder = write_observation(obs, args.out / side)
        if args.with_truth:
            (folder / "true_camera.json").write_text(
                json.dumps(to_jsonable(truth["camera"]), indent=1) + "\n"
            )
        elif (folder / "true_camera.json").exists():
            (folder / "true_camera.json").unlink()  # a stale one would not match camera.json
        dt, dr = truth["calibration_error"]
        calib = f", calibration off by {1000 * dt:.1f} mm / {math.degrees(dr):.2f}°" if dt else ""
        print(f"{folder}: {side} from {label}, realism {args.realism}{calib}")
    return 0


def _crop(value: str) -> tuple[int, int, int, int]:
    try:
        x, y, w, h = (int(v) for v in value.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError("expected X,Y,W,H (pixels)") from None
    if min(x, y) < 0 or min(w, h) < 1:
        raise argparse.ArgumentTypeError("expected X,Y ≥ 0 and W,H ≥ 1")
    return x, y, w, h


def show(args: argparse.Namespace) -> int:
    from PIL import Image

    from sim.observation import contact_sheet

    if args.tile_width < 16:
        raise UsageError(f"--tile-width {args.tile_width}: must be ≥ 16 px")
    if args.colors is not None and not 2 <= args.colors <= 256:
        raise UsageError(f"--colors {args.colors}: must be in 2..256")
    domain, inst = _checked(args.instance)
    title = f"{domain.name} {inst.name}".strip()
    sides = {"start": [("start", inst.start)], "goal": [("goal", inst.goal)]}
    scenes = sides.get(args.side, sides["start"] + sides["goal"])
    cameras = [_camera(domain, c) for c in (args.camera or list(domain.cameras))]
    columns = [(Path(lbl).stem, cam) for lbl, cam in cameras]
    if args.crop:
        for lbl, cam in cameras:
            w, h = (
                (cam["width"], cam["height"])
                if isinstance(cam, dict)
                else (
                    domain.cameras[cam].width,
                    domain.cameras[cam].height,
                )
            )
            x, y, cw, ch = args.crop
            if x + cw > w or y + ch > h:
                raise UsageError(f"--crop {x},{y},{cw},{ch} exceeds {lbl}'s {w}×{h} image")
    sheet = contact_sheet(
        domain,
        scenes,
        cameras=columns,
        title=title,
        realism=args.realism or None,
        seed=args.seed,
        tile_width=args.tile_width,
        crop=args.crop,
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    img = Image.fromarray(sheet)
    if args.colors:  # a palette PNG: several times smaller, for documentation
        img = img.quantize(args.colors, method=Image.Quantize.FASTOCTREE)
    img.save(args.out, optimize=True)
    levels = f" under {', '.join(args.realism)}" if args.realism else ""
    print(f"{args.out}: {args.side} from {', '.join(c for c, _ in columns)}{levels}")
    return 0


def benchmark(args: argparse.Namespace) -> int:
    """Write (or with --check verify) a domain's benchmark files of one split, every scene
    settled in MuJoCo and every order executable by the robot."""
    import json
    import time

    import domains
    from domains.benchmark import benchmark_keys, dumps, same
    from sim.settle import physical_problems

    domain = domains.load(args.domain)
    folder = domain.benchmark_dir_of(args.split)
    if not args.check:
        folder.mkdir(parents=True, exist_ok=True)
    differ = []
    for g, s in benchmark_keys():
        t0 = time.perf_counter()
        inst = domain.benchmark_instance(
            g, s, physics=physical_problems, grasps=True, split=args.split
        )
        path = domain.benchmark_path(g, s, args.split)
        value = inst.to_dict()
        if args.check:
            if not path.exists() or not same(json.loads(path.read_text()), value):
                differ.append(inst.name)
        else:
            path.write_text(dumps(value))
            took = time.perf_counter() - t0
            print(f"{path}: {len(inst.order)} steps ({took:.1f} s)", flush=True)
    if differ:
        print(f"{args.domain}: regenerated instances differ: {', '.join(differ)}", file=sys.stderr)
        return 1
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "scene",
        help="generate, render and show scene instances",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    scene_sub = p.add_subparsers(dest="scene_command", metavar="SUBCOMMAND", parser_class=type(p))
    scene_sub.required = True

    g = scene_sub.add_parser("generate", help="draw an instance (start, goal, construction order)")
    g.add_argument("domain", metavar="DOMAIN")
    g.add_argument("--seed", type=int, required=True)
    g.add_argument(
        "--split",
        choices=("dev", "test"),
        default="dev",
        help="draw from the dev or the test split's goal and start families (default: dev)",
    )
    g.add_argument("--out", type=Path, required=True, metavar="INSTANCE.json")
    g.set_defaults(handler=generate)

    r = scene_sub.add_parser("render", help="write DIR/start/ and DIR/goal/ observation folders")
    r.add_argument("instance", metavar="INSTANCE.json")
    r.add_argument("--out", type=Path, required=True, metavar="DIR")
    r.add_argument("--view", choices=VIEWS, help="a named view of the domain (default: front)")
    r.add_argument(
        "--camera",
        metavar="NAME|FILE.json",
        help="a named view, or a camera file (docs/observations.md): the TRUE camera",
    )
    r.add_argument(
        "--realism",
        choices=LEVELS,
        default="clean",
        help="sensor, lighting and calibration realism (default: clean, the exact protocol)",
    )
    r.add_argument("--clean-depth", action="store_true", help="no depth sensor noise")
    r.add_argument(
        "--seed", type=int, default=0, help="seed of every random effect (goal: seed + 1)"
    )
    r.add_argument(
        "--with-truth",
        action="store_true",
        help="also write true_camera.json (host-only ground truth; never for a policy)",
    )
    r.set_defaults(handler=render)

    s = scene_sub.add_parser("show", help="a PNG contact sheet: start and goal from every camera")
    s.add_argument("instance", metavar="INSTANCE.json")
    s.add_argument("--out", type=Path, required=True, metavar="SHEET.png")
    s.add_argument(
        "--camera",
        action="append",
        metavar="NAME|FILE.json",
        help="a column: a named view or a camera file (repeatable; default: the domain's views)",
    )
    s.add_argument(
        "--realism",
        action="append",
        choices=LEVELS,
        help="rows per level (repeatable; default: the clean render)",
    )
    s.add_argument("--side", choices=("start", "goal", "both"), default="both")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--tile-width", type=int, default=640, metavar="W")
    s.add_argument("--crop", type=_crop, metavar="X,Y,W,H", help="show this part of each image")
    s.add_argument(
        "--colors", type=int, metavar="N", help="save a palette PNG of N ≤ 256 colours (smaller)"
    )
    s.set_defaults(handler=show)

    b = scene_sub.add_parser(
        "benchmark",
        help="write or verify (--check) a domain's benchmark files (20 goals × 3 starts)",
        description=(
            "Write (or with --check compare) the benchmark files of one split: dev in "
            "domains/DOMAIN/benchmark/, test in domains/DOMAIN/benchmark/test/ (goal "
            "families the dev split never uses; docs/domains.md, Splits)."
        ),
    )
    b.add_argument("domain", metavar="DOMAIN")
    b.add_argument(
        "--split",
        choices=("dev", "test"),
        default="dev",
        help="which split (default: dev, the set programs are developed on)",
    )
    b.add_argument("--check", action="store_true", help="compare with the files instead of writing")
    b.set_defaults(handler=benchmark)


if __name__ == "__main__":
    from rivet.cli import main

    sys.exit(main(["scene", *sys.argv[1:]]))
