"""How often `rivet solve`'s fit (`artifacts.fit`) refuses: a frozen set's programs on the
observations of a benchmark split — its own domain's (where every refusal is a false one) or
another domain's (where every acceptance is a miss). The observations are the trials' own
(`sim.trials.observations`: the same seeds, camera and realism as `rivet eval`).

    python -m benchmarks.solve_fit --domain cubes [--images assembly] [--split dev] [--trials 60]
        [--camera front|view1|view2|FILE.json ...]
"""

from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--domain", required=True, help="the frozen set's domain")
    p.add_argument("--images", default=None, help="whose observations (default: the domain's)")
    p.add_argument("--split", choices=("dev", "test"), default="dev")
    p.add_argument("--trials", type=int, default=60)
    p.add_argument(
        "--camera",
        nargs="+",
        default=["front"],
        help="views of the domain or camera files (docs/cameras/*.json), each in turn",
    )
    p.add_argument("--sandbox", choices=("docker", "local"), default="docker")
    args = p.parse_args(argv)

    import domains
    import sandbox
    from artifacts import load
    from artifacts.fit import scene_fit
    from sim.observation import load_camera
    from sim.trials import HONEST, observations

    own = domains.load(args.domain)
    source = domains.load(args.images or args.domain)
    options = {"quiet": True} if args.sandbox == "local" else {}
    with (
        sandbox.open_executor(args.sandbox, **options) as executor,
        load(own.name).runner(executor) as run,
    ):
        for name in args.camera:
            camera = name if name in source.cameras else load_camera(name)
            fits, refused = 0, []
            worst = {"unexplained": 0.0, "residual_m": 0.0, "support": 1.0}
            for inst in source.benchmark(split=args.split)[: args.trials]:
                for side, obs in zip(
                    ("start", "goal"), observations(source, inst, camera, HONEST), strict=True
                ):
                    try:
                        records = run.perceive(obs)
                    except Exception as e:  # a program failing on foreign images: a refusal too
                        refused.append(f"{inst.name} {side}: perceive failed: {str(e)[:120]}")
                        continue
                    fit = scene_fit(own, obs, records, run.render)
                    judged = [o for o in fit.objects if o.support is not None]
                    worst["unexplained"] = max(worst["unexplained"], fit.unexplained)
                    worst["residual_m"] = max(
                        [worst["residual_m"], *(o.residual_m or 0 for o in judged)]
                    )
                    worst["support"] = min([worst["support"], *(o.support or 0 for o in judged)])
                    if fit.ok:
                        fits += 1
                    else:
                        refused.append(f"{inst.name} {side}: {fit.problems[0]}")
            n = fits + len(refused)
            print(
                f"{own.name} programs on {source.name} {args.split} observations through "
                f"{name}: {fits}/{n} fit, {len(refused)} refused; worst unexplained "
                f"{100 * worst['unexplained']:.1f} %, residual "
                f"{1000 * worst['residual_m']:.1f} mm, support {100 * worst['support']:.0f} %",
                flush=True,
            )
            for line in refused[:10]:
                print(f"  refused {line}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
