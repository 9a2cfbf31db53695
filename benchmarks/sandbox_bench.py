"""Sandbox figures: cold start, and the warm per-job overhead over an in-process call.

- cold start: from creating a Docker executor (new container) to the first job's verdict,
  for a trivial job, median of `COLD_RUNS`. The harness answers jobs while it is still
  importing the heavy modules (between jobs), so this is also reported up to the point where
  every heavy module is imported.
- warm overhead: with the harness warm (heavy modules imported), the median round trip of
  `WARM_JOBS` jobs minus the median in-process call of the same function on the same inputs.
Targets (issue 5): warm overhead <= 50 ms, cold start <= 2 s.

`--against IMAGE` compares the warm overhead with another sandbox image (an earlier commit's
harness) instead: one warm executor each, jobs interleaved, so that both see the same load.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
import types
from typing import Any

import numpy as np

from sandbox import Job
from sandbox.docker_backend import DockerExecutor
from sandbox.image import ensure_image

COLD_RUNS = 5
WARM_JOBS = 60
TARGET_WARM_MS = 50.0
TARGET_COLD_S = 2.0
CASES: dict[str, tuple[str, dict[str, Any]]] = {
    "add": ("def f(x):\n    return x + 1\n", {"x": 41}),
    "numpy_4x4": (
        "import numpy as np\ndef f(T, p):\n    return {'q': T[:3, :3] @ p + T[:3, 3:]}\n",
        {"T": np.eye(4), "p": np.ones((3, 100))},
    ),
}


def _in_process(source: str, inputs: dict[str, Any], n: int) -> list[float]:
    module = types.ModuleType("draft")
    exec(compile(source, "draft.py", "exec"), module.__dict__)
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        module.f(**inputs)
        times.append(time.perf_counter() - t0)
    return times


def _cold(image: str) -> dict[str, float]:
    starts, firsts, warms = [], [], []
    job = Job(source=CASES["add"][0], function="f", inputs=CASES["add"][1])
    for _ in range(COLD_RUNS):
        t0 = time.perf_counter()
        with DockerExecutor(image=image) as ex:
            ex.start()
            started = time.perf_counter() - t0
            assert ex.run(job).ok
            firsts.append(time.perf_counter() - t0)
            ex.warm()
            warms.append(time.perf_counter() - t0)
        starts.append(started)
    return {
        "container_to_harness_ready_s": statistics.median(starts),
        "cold_start_to_first_verdict_s": statistics.median(firsts),
        "cold_start_max_s": max(firsts),
        "cold_start_to_all_modules_imported_s": statistics.median(warms),
    }


def _warm(image: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    with DockerExecutor(image=image) as ex:
        status = ex.warm()
        out["preload_s"] = status["preload_s"]
        for name, (source, inputs) in CASES.items():
            job = Job(source=source, function="f", inputs=inputs)
            for _ in range(3):
                ex.run(job)
            trips, child = [], []
            for _ in range(WARM_JOBS):
                t0 = time.perf_counter()
                report = ex.run(job)
                trips.append(time.perf_counter() - t0)
                child.append(report.wall_time_s)
                assert report.ok, report
            local = statistics.median(_in_process(source, inputs, WARM_JOBS))
            out[name] = {
                "jobs": WARM_JOBS,
                "sandbox_median_ms": 1000 * statistics.median(trips),
                "sandbox_p90_ms": 1000 * statistics.quantiles(trips, n=10)[-1],
                "child_fork_to_exit_median_ms": 1000 * statistics.median(child),
                "in_process_median_ms": 1000 * local,
                "overhead_median_ms": 1000 * (statistics.median(trips) - local),
            }
    return out


def _against(image: str, other: str, jobs: int) -> dict[str, Any]:
    """Warm overhead of `image` and `other`, jobs interleaved (ABBA) on two warm executors."""
    out: dict[str, Any] = {"image": image, "against": other, "jobs": jobs}
    with DockerExecutor(image=image) as new, DockerExecutor(image=other) as old:
        new.warm()
        old.warm()
        for name, (source, inputs) in CASES.items():
            job = Job(source=source, function="f", inputs=inputs)
            trips: dict[str, list[float]] = {"image": [], "against": []}
            for i in range(jobs):
                pair = (("image", new), ("against", old))
                for side, ex in pair if i % 2 else pair[::-1]:
                    t0 = time.perf_counter()
                    report = ex.run(job)
                    trips[side].append(time.perf_counter() - t0)
                    assert report.ok, report
            local = statistics.median(_in_process(source, inputs, jobs))
            out[name] = {
                f"{side}_overhead_median_ms": 1000 * (statistics.median(t) - local)
                for side, t in trips.items()
            }
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="benchmarks.sandbox_bench")
    parser.add_argument("--against", metavar="IMAGE", help="compare with this sandbox image")
    parser.add_argument("--jobs", type=int, default=200, help="with --against: jobs per side")
    args = parser.parse_args(argv)
    image = ensure_image(quiet=True)
    if args.against:
        print(json.dumps(_against(image, args.against, args.jobs), indent=2))
        return 0
    cold = _cold(image)
    warm = _warm(image)
    figures = {"image": image, "cold": cold, "warm": warm}
    print(json.dumps(figures, indent=2))
    worst = max(v["overhead_median_ms"] for k, v in warm.items() if isinstance(v, dict))
    cold_s = cold["cold_start_to_first_verdict_s"]
    print(
        f"warm overhead (median of {WARM_JOBS}): {worst:.1f} ms (target <= {TARGET_WARM_MS:.0f} ms) "
        f"{'OK' if worst <= TARGET_WARM_MS else 'MISSED'}"
    )
    print(
        f"cold start (median of {COLD_RUNS}): {cold_s:.2f} s (target <= {TARGET_COLD_S:.0f} s) "
        f"{'OK' if cold_s <= TARGET_COLD_S else 'MISSED'}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
