"""Scale-out against a local Ray instance: trials fan out to Ray actors and come back in order."""

from __future__ import annotations

import pytest

import domains
from experiments.evaluation import EvalConfig, run_eval
from sim.settle import physical_problems

ray = pytest.importorskip("ray")  # the optional extra; `make test` installs it

PROGRAMS = {
    "render": "def render(records, meshes, camera):\n    raise NotImplementedError\n",
    "perceive": "def perceive(observation, meshes, camera):\n    return []\n",
    "relate": "RELATIONS = {}\n\ndef relate(records, meshes):\n    return {'directed': True, 'multigraph': True, 'graph': {}, 'nodes': [], 'edges': []}\n",
    "plan": "import numpy as np\n\ndef plan(start, goal, meshes):\n    return {'status': 'ok', 'steps': [{'object': 'magenta', 'target_pose': np.eye(4)}]}\n",
}


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield "local"
    ray.shutdown()


@pytest.mark.slow
def test_eval_trials_fan_out_to_ray_actors(tmp_path, local_ray):
    for name, src in PROGRAMS.items():
        (tmp_path / f"{name}.py").write_text(src)
    d = domains.load("cubes")
    instances = [d.benchmark_instance(g, 1, physics=physical_problems).to_dict() for g in (1, 2, 3)]
    config = EvalConfig(domain="cubes", policy=("programs", str(tmp_path)))
    summary = run_eval(config, instances, workers=2, ray_address=local_ray)
    assert [t["name"] for t in summary["per_trial"]] == [i["name"] for i in instances]
    assert summary["final_sr"] == 0.0
    for t in summary["per_trial"]:
        assert t["failure"]["stage"] == "perception"  # saw nothing
        assert t["execution_failure"]["kind"] == "unknown_object"
