"""`rivet scene …`: generate instances, render their observations, draw contact sheets.

    rivet scene generate DOMAIN --seed S --out INSTANCE.json
    rivet scene render INSTANCE.json --out DIR [--camera front] [--clean-depth] [--seed N]
    rivet scene show INSTANCE.json --out SHEET.png

INSTANCE.json may also be a benchmark name such as ``cubes/goal01_start1``. Instances are
checked before use: malformed or physically invalid ones (interpenetrating, outside the
workspace, not at rest) are refused with exit code 2 and a message naming the object.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _checked(arg: str):
    import sim  # noqa: F401  (sets the headless GL default before MuJoCo loads)
    from sim.scene import load_instance
    from sim.settle import validate_scene

    domain, inst = load_instance(arg)
    validate_scene(domain, inst.start, where="start")
    validate_scene(domain, inst.goal, where="goal")
    return domain, inst


def generate(args: argparse.Namespace) -> int:
    import domains
    from domains.benchmark import dumps

    domain = domains.load(args.domain)
    inst = domain.generate(args.seed)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(dumps(inst.to_dict()))
    print(f"{args.out}: {domain.name} seed {args.seed}, {len(inst.order)} construction steps")
    return 0


def render(args: argparse.Namespace) -> int:
    from artifacts.observations import write_observation
    from sim.observation import DEFAULT_NOISE, observe

    domain, inst = _checked(args.instance)
    noise = None if args.clean_depth else DEFAULT_NOISE
    for k, (side, scene) in enumerate((("start", inst.start), ("goal", inst.goal))):
        obs = observe(domain, scene, args.camera, noise=noise, seed=args.seed + k)
        folder = write_observation(obs, args.out / side)
        print(f"{folder}: {side} from {args.camera}")
    return 0


def show(args: argparse.Namespace) -> int:
    from PIL import Image

    from sim.observation import contact_sheet

    domain, inst = _checked(args.instance)
    title = f"{domain.name} {inst.name}".strip()
    sheet = contact_sheet(domain, [("start", inst.start), ("goal", inst.goal)], title=title)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(sheet).save(args.out)
    print(f"{args.out}: start and goal from {', '.join(domain.cameras)}")
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
    g.add_argument("--out", type=Path, required=True, metavar="INSTANCE.json")
    g.set_defaults(handler=generate)

    r = scene_sub.add_parser("render", help="write DIR/start/ and DIR/goal/ observation folders")
    r.add_argument("instance", metavar="INSTANCE.json")
    r.add_argument("--out", type=Path, required=True, metavar="DIR")
    r.add_argument("--camera", default="front", choices=("front", "view1", "view2"))
    r.add_argument("--clean-depth", action="store_true", help="no depth sensor noise")
    r.add_argument("--seed", type=int, default=0, help="seed of the depth noise")
    r.set_defaults(handler=render)

    s = scene_sub.add_parser("show", help="a PNG contact sheet: start and goal from every camera")
    s.add_argument("instance", metavar="INSTANCE.json")
    s.add_argument("--out", type=Path, required=True, metavar="SHEET.png")
    s.set_defaults(handler=show)


if __name__ == "__main__":
    from rivet.cli import main

    sys.exit(main(["scene", *sys.argv[1:]]))
