"""Online latency of the thin runtime: `System.solve` (perceive ×2, relate ×2, plan) on the first
trials of each domain's benchmark that has frozen artifacts. Observations are rendered first and
not timed; the figure is what `rivet solve` spends after reading its folders."""

from __future__ import annotations

import statistics
import sys
import time

N = 12


def main() -> int:
    import domains
    from artifacts import ArtifactError, load
    from sim.observation import observe

    for name in domains.names():
        d = domains.load(name)
        try:
            system = load(name)
        except ArtifactError as e:
            print(f"{name}: skipped ({e})")
            continue
        times = []
        for inst in d.benchmark()[:N]:
            start = observe(d, inst.start, "front", seed=1)
            goal = observe(d, inst.goal, "front", seed=2)
            t = time.perf_counter()
            system.solve(start, goal)
            times.append(time.perf_counter() - t)
        print(
            f"{name}: solve latency over {len(times)} trials: median {1000 * statistics.median(times):.0f} ms, "
            f"max {1000 * max(times):.0f} ms"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
