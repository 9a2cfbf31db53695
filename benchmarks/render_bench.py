"""Rendering figures: the cost of one RGB-D observation, per domain and camera.

- first observation: compiling the scene's MuJoCo model and opening the EGL context;
- one observation (the target, issue 3: < 0.5 s on the 2-core development machine):
  RGB + clean depth + the depth sensor model, model and context already built, median of
  `RUNS`; also split into its parts;
- writing the observation folder (rgb.png, depth.png, camera.json).
Scenes are each domain's benchmark goal 1 (the authoring reference) at 1280×720.
"""

from __future__ import annotations

import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import domains
import sim  # noqa: F401  (headless GL default before MuJoCo loads)
from artifacts.observations import write_observation
from sim.observation import DEFAULT_NOISE, apply_depth_noise, observe, renderer_for
from sim.scene import scene_model

RUNS = 10
TARGET_S = 0.5


def _median(f, n: int = RUNS) -> float:
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def bench(name: str) -> dict:
    d = domains.load(name)
    inst = d.benchmark()[0]
    scene = inst.goal
    t0 = time.perf_counter()
    observe(d, scene, "front")
    first = time.perf_counter() - t0
    out = {"domain": name, "first_observation_s": round(first, 3)}
    for cam in d.cameras:
        out[f"observation_{cam}_s"] = round(_median(lambda cam=cam: observe(d, scene, cam)), 4)
    sm = scene_model(d, scene)
    front = d.camera("front")
    r = renderer_for(sm.model, front["width"], front["height"])
    out["rgb_and_depth_s"] = round(_median(lambda: r.render(sm.data, front)), 4)
    depth = r.render(sm.data, front)["depth"]
    rng = np.random.default_rng(0)
    out["depth_noise_s"] = round(_median(lambda: apply_depth_noise(depth, rng, DEFAULT_NOISE)), 4)
    out["with_mask_s"] = round(_median(lambda: observe(d, scene, "front", mask=True), 5), 4)
    obs = observe(d, scene, "front")
    with tempfile.TemporaryDirectory() as tmp:
        out["write_folder_s"] = round(
            _median(lambda: write_observation(obs, Path(tmp) / "o"), 5), 4
        )
    return out


def main() -> int:
    results = [bench(n) for n in domains.names()]
    for r in results:
        print(json.dumps(r))
    worst = max(r[k] for r in results for k in r if k.startswith("observation_"))
    ok = worst < TARGET_S
    print(
        f"one observation (1280×720 RGB + depth + noise): worst median {worst * 1000:.0f} ms "
        f"(target < {TARGET_S * 1000:.0f} ms): {'ok' if ok else 'MISSED'}"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
