"""Online latency of the thin runtime: `Runner.solve` (perceive ×2, relate ×2, plan) on the first
trials of each domain's dev benchmark that has frozen artifacts, in a Docker sandbox session as
`rivet solve` runs them. Observations are rendered first and not timed. Reported per stage: CPU
time of the calls (measured outside the programs, what the online budget limits), wall time of
the calls, and the round trip with the sandbox's transfers; and the solve's overhead beyond the
programs' own CPU — round trip minus the five calls' CPU, and their ratio — the median over the
trials (target: at most 100 ms).

    python -m benchmarks.solve_bench [--trials N]   (default 12; 60: the whole dev split)
"""

from __future__ import annotations

import argparse
import statistics
import sys

N = 12


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.solve_bench", description=__doc__)
    p.add_argument("--trials", type=int, default=N, help="the dev split's first N trials")
    args = p.parse_args(argv)
    if args.trials < 1:
        p.error("--trials must be at least 1")
    import domains
    import sandbox
    from artifacts import ArtifactError, load
    from sim.observation import observe

    with sandbox.open_executor("docker") as executor:
        for name in domains.names():
            d = domains.load(name)
            try:
                system = load(name)
            except ArtifactError as e:
                print(f"{name}: skipped ({e})")
                continue
            cpu: dict[str, list[float]] = {}
            round_trip = []
            overhead, ratio = [], []
            with system.runner(executor) as run:
                for inst in d.benchmark()[: args.trials]:
                    start = observe(d, inst.start, "front", seed=1)
                    goal = observe(d, inst.goal, "front", seed=2)
                    run.solve(start, goal)
                    for stage, seconds in run.cpu.items():
                        cpu.setdefault(stage, []).append(seconds)
                    round_trip.append(run.timings["round_trip"])
                    overhead.append(run.timings["round_trip"] - run.cpu["total"])
                    ratio.append(run.timings["round_trip"] / run.cpu["total"])
            stages = ", ".join(
                f"{s} {1000 * statistics.median(cpu[s]):.0f}"
                for s in ("perceive", "relate", "plan")
            )
            print(
                f"{name}: over {len(round_trip)} trials, median CPU ms: {stages}; "
                f"round trip median {1000 * statistics.median(round_trip):.0f} ms, "
                f"max {1000 * max(round_trip):.0f} ms; overhead beyond the programs' CPU: "
                f"median {1000 * statistics.median(overhead):.0f} ms (wall / CPU "
                f"{statistics.median(ratio):.2f})"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
