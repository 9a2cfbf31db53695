"""How often `perceive` misreads the scenes a closed loop looks at, and whether a second look
of the same scene repeats the misreading.

    python -m benchmarks.loop_looks --domain cubes --camera docs/cameras/envelope-1.json
        [--split dev] [--trials N] [--programs DIR] [--json OUT]

For each of the split's first N instances, the scenes after each step of its reference order
(each object where its step puts it: what a closed loop's looks see when every transfer
lands) are observed twice, with fresh sensor noise and the trial's realism and calibration,
and read by `perceive` in a local sandbox session as a trial calls it; each reading is scored
as `property.accuracy` scores it (`sim.score.state_accuracy`). Prints each misread scene —
which look, the objects off and by how much ([mm, °]), whether the relations differ — and the
totals: looks wrong, and scenes read wrong by both looks (what `sim.loop.ClosedLoop`'s second
look cannot dismiss).

The local backend isolates nothing: run it on programs you trust (the people-written ones).
"""

from __future__ import annotations

import argparse
import json
import sys
import zlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

LOOKS = 2


def scenes_of(instance) -> list[dict]:
    """The scenes after each step of `instance`'s reference order (the start first)."""
    objects = [dict(o, pose=np.asarray(o["pose"], float)) for o in instance.start["objects"]]
    index = {o["id"]: k for k, o in enumerate(objects)}
    out = [{"objects": [dict(o) for o in objects]}]
    for step in instance.order:
        k = index[step["object"]]
        objects[k] = dict(objects[k], pose=np.asarray(step["target_pose"], float))
        out.append({"objects": [dict(o) for o in objects]})
    return out


def misreads(
    domain_name: str,
    sources: Mapping[str, str],
    camera: Any,
    instances: Sequence,
    progress: Callable[[str], None] = lambda _: None,
) -> tuple[list[dict], dict]:
    """(one row per look read wrong, totals) for `instances` seen through `camera`."""
    import domains
    from benchmarks.perceive_draws import wrong_reading
    from checks.calls import session_modules
    from checks.context import DomainSpec
    from checks.inputs import records
    from sandbox import MESHES, Program
    from sandbox.local_backend import LocalExecutor
    from sim.observation import observe
    from sim.score import state_accuracy

    dom = domains.load(domain_name)
    spec = DomainSpec.of(dom)
    others = {k: v for k, v in sources.items() if k != "perceive"}
    program = Program(
        modules=session_modules("perceive", sources["perceive"], others), meshes=spec.meshes
    )
    rows: list[dict] = []
    totals = {"scenes": 0, "looks": 0, "looks_wrong": 0, "scenes_wrong_twice": 0}
    with LocalExecutor(quiet=True) as ex, ex.open_session(program, load_timeout_s=120) as s:
        if not s.load.ok:
            raise SystemExit(f"the programs do not load: {s.load}")
        for inst in instances:
            calibration = zlib.crc32(f"{inst.name}/camera".encode())
            for k, scene in enumerate(scenes_of(inst)):
                truth = records(scene)
                wrong = 0
                for look in range(LOOKS):
                    obs = observe(
                        dom,
                        {"domain": dom.name, **scene},
                        camera,
                        seed=zlib.crc32(f"{inst.name}/{k}/{look}".encode()),
                        realism="default",
                        calibration_seed=calibration,
                    )
                    got = s.call("perceive", "perceive", obs, MESHES, obs["camera"], timeout_s=60)
                    totals["looks"] += 1
                    row = {"instance": inst.name, "scene": k, "look": look}
                    if got.verdict != "ok":
                        rows.append({**row, "error": f"{got.verdict}: {got.detail}"[:300]})
                        wrong += 1
                        continue
                    score = state_accuracy(dom, got.value, truth)
                    if score.correct:
                        continue
                    wrong += 1
                    rows.append({**row, **wrong_reading(score)})
                totals["scenes"] += 1
                totals["looks_wrong"] += wrong
                totals["scenes_wrong_twice"] += wrong == LOOKS
            progress(
                f"{inst.name}: {totals['looks_wrong']} of {totals['looks']} looks wrong so far"
            )
    return rows, totals


def main(argv: list[str] | None = None) -> int:
    import domains
    from benchmarks.perceive_draws import program_sources

    p = argparse.ArgumentParser(prog="python -m benchmarks.loop_looks", description=__doc__)
    p.add_argument("--domain", required=True)
    p.add_argument("--camera", default="front", help="a named view or a camera file")
    p.add_argument("--split", default="dev", choices=("dev", "test"))
    p.add_argument("--trials", type=int, default=10, help="the split's first N instances")
    p.add_argument("--programs", type=Path, help="default: domains/DOMAIN/programs")
    p.add_argument("--json", type=Path, help="write the rows and totals here")
    args = p.parse_args(argv)
    if args.trials < 1:
        p.error("--trials must be at least 1")
    dom = domains.load(args.domain)
    camera = args.camera
    if Path(camera).suffix == ".json":
        camera = json.loads(Path(camera).read_text())
    sources = program_sources(args.domain, args.programs)
    instances = dom.benchmark(args.split)[: args.trials]
    rows, totals = misreads(
        args.domain, sources, camera, instances, lambda line: print(line, file=sys.stderr)
    )
    for r in rows:
        print(json.dumps(r))
    print(
        f"{args.domain}: {totals['looks_wrong']} of {totals['looks']} looks wrong over "
        f"{totals['scenes']} scenes; {totals['scenes_wrong_twice']} scenes wrong on both looks"
    )
    if args.json:
        args.json.write_text(json.dumps({"totals": totals, "wrong": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
