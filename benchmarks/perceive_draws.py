"""How often a `perceive` program gets a drawn check observation wrong.

    python -m benchmarks.perceive_draws --domain cubes --seeds 1 2 3 [--programs DIR]
    python -m benchmarks.perceive_draws --domain assembly --seeds 201 202 --azimuth 40 75

Draws the `perceive` check's observations from each case seed (`checks.inputs.build_cases`, the
default budget: 45 a seed), calls the program on each in a local sandbox session, exactly as
the check calls it, and scores it as `property.accuracy` does (`sim.score.state_accuracy`).
`--azimuth LO HI` draws every camera from that slice of the domain's camera envelope (no named
view, no hiding case; azimuth 0 looks from +x, the robot's side): a slice where parts hide
behind structures can be far weaker than the whole envelope (docs/checks.md: the assembly
`perceive` by side of the envelope).
Prints every wrong observation (case, camera, the objects off and by how much) and the rate,
and how many readings could not stand as perceived (`geometry.scene_problems` at the trials'
tolerances: parts interpenetrating by more than `TOLERANCES.penetration`, unsupported or
tipping) — a reading can be accurate and still put parts inside each other, which the executor
then meets at the grasp.
A program that is wrong on a fraction p of observations passes a check of n with probability
(1 - p)^n: at 45 observations, p = 1 % passes 64 % of draws, p = 0.1 % passes 96 %.

The local backend isolates nothing: run it on programs you trust (the people-written ones).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def wrong_reading(score) -> dict:
    """What a reading `sim.score.state_accuracy` found wrong: the ids missing and extra, the
    objects off ([mm, °]) and whether the relations differ."""
    return {
        "missing": score.missing,
        "extra": score.extra,
        "off": {
            o.id: [round(1000 * o.translation, 1), round(float(np.degrees(o.rotation)), 1)]
            for o in score.objects
            if not o.within
        },
        "relations": bool(score.missing_edges or score.extra_edges),
    }


def drawn_observations(domain, seed: int, azimuth: tuple[float, float] | None) -> list[dict]:
    """The perceive check's observations of case seed `seed` or, with `azimuth`, as many drawn
    the same way through cameras of that slice of the envelope only."""
    import dataclasses

    from checks.budget import DEFAULT
    from checks.inputs import build_cases, perceive_cases

    if azimuth is None:
        return build_cases(domain, "perceive", DEFAULT, seed)["observations"]
    envelope = dataclasses.replace(domain.camera_envelope, azimuth=azimuth)
    budget = dataclasses.replace(DEFAULT, name="side", hidden=0)
    return perceive_cases(domain, budget, seed, envelope=envelope)


def wrong_observations(
    domain_name: str,
    sources: dict[str, str],
    seeds: list[int],
    progress,
    azimuth: tuple[float, float] | None = None,
):
    import domains
    from checks.calls import session_modules
    from checks.context import DomainSpec
    from checks.suites.perceive import reading_score
    from geometry import scene_problems
    from sandbox import MESHES, Program
    from sandbox.local_backend import LocalExecutor

    dom = domains.load(domain_name)
    spec = DomainSpec.of(dom)
    others = {k: v for k, v in sources.items() if k != "perceive"}
    program = Program(
        modules=session_modules("perceive", sources["perceive"], others), meshes=spec.meshes
    )
    rows, total, invalid = [], 0, []
    with LocalExecutor(quiet=True) as ex, ex.open_session(program, load_timeout_s=120) as s:
        if not s.load.ok:
            raise SystemExit(f"the programs do not load: {s.load}")
        for seed in seeds:
            t0 = time.perf_counter()
            cases = drawn_observations(dom, seed, azimuth)
            built = time.perf_counter() - t0
            wrong = 0
            for case in cases:
                total += 1
                got = s.call(
                    "perceive", "perceive", case["observation"], MESHES, case["camera"],
                    timeout_s=60,
                )  # fmt: skip
                row = {"seed": seed, "case": case["name"], "camera": case["camera_name"]}
                if got.verdict != "ok":
                    rows.append({**row, "error": f"{got.verdict}: {got.detail}"[:300]})
                    wrong += 1
                    continue
                known = [o for o in got.value if o.get("mesh") in spec.geometry]
                problems = scene_problems(known, spec.geometry)
                if problems:
                    invalid.append({**row, "problems": problems[:3]})
                score, untold = reading_score(dom, spec.meshes, case, got.value)
                if untold:  # not scored, as in property.accuracy: the image cannot tell them
                    row["untold"] = sorted(untold)
                    if score.correct:
                        progress(
                            f"  {case['name']}: cannot be told from the truth: {row['untold']}"
                        )
                if score.correct:
                    continue
                wrong += 1
                rows.append({**row, **wrong_reading(score)})
            progress(
                f"seed {seed}: {wrong} of {len(cases)} wrong "
                f"({built:.0f} s to draw, {time.perf_counter() - t0 - built:.0f} s to perceive)"
            )
    return rows, total, invalid


def program_sources(domain: str, folder: Path | None = None) -> dict[str, str]:
    """The programs of `folder` (default: the domain's people-written ones), by function."""
    from contracts.functions import FUNCTIONS

    folder = folder or REPO / "domains" / domain / "programs"
    return {
        f: (folder / f"{f}.py").read_text() for f in FUNCTIONS if (folder / f"{f}.py").is_file()
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.perceive_draws", description=__doc__)
    p.add_argument("--domain", required=True)
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--programs", type=Path, help="default: domains/DOMAIN/programs")
    p.add_argument("--json", type=Path, help="write the wrong observations here")
    p.add_argument(
        "--azimuth",
        type=float,
        nargs=2,
        metavar=("LO", "HI"),
        help="draw every camera from this azimuth slice of the envelope [deg]",
    )
    args = p.parse_args(argv)
    azimuth = None
    if args.azimuth is not None:
        import domains

        lo, hi = args.azimuth
        full = domains.load(args.domain).camera_envelope.azimuth
        if not full[0] <= lo < hi <= full[1]:
            p.error(
                f"--azimuth {lo:g} {hi:g}: need LO < HI within the {args.domain} envelope's "
                f"azimuth, {full[0]:g} to {full[1]:g} degrees"
            )
        azimuth = (lo, hi)
    sources = program_sources(args.domain, args.programs)
    rows, total, invalid = wrong_observations(
        args.domain,
        sources,
        args.seeds,
        lambda line: print(line, file=sys.stderr, flush=True),
        azimuth,
    )
    for r in rows:
        print(json.dumps(r))
    for r in invalid:
        print(json.dumps({"could_not_stand": r}))
    print(
        f"{args.domain}: {len(rows)} of {total} drawn observations wrong ({100 * len(rows) / max(total, 1):.1f} %); "
        f"{len(invalid)} readings could not stand as perceived"
    )
    if args.json:
        out = {"total": total, "wrong": rows, "could_not_stand": invalid}
        args.json.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
