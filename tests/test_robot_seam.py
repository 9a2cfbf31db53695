"""The robot behind one seam: every consumer is built from the description in
`geometry.robot` (`ROBOT`, or the JSON file `RIVET_ROBOT` names).

The seam test describes another hand — fingertips reaching 30 mm out from the pads instead of
17 mm, the tool centre 10 mm farther out, a narrower wrist range, a noisier wrist camera, other
names — and sees the change in the simulator's robot, the IK, the hand model, the executor's
in-hand estimate, the toolbox's facts and documentation, a check's rule, a prompt and the frozen
sets' toolbox hash."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from geometry.robot import DEFAULT, ENV, ROBOT, Robot, load

REPO = Path(__file__).resolve().parents[1]

PROBE = r"""
import json
import numpy as np
import trimesh

import domains
from agent.context import build_context
from agent.prompt import build_request
from artifacts.hashing import robot_hash
from checks.rulebook import rules_for
from contracts.functions import CODE_DEPS
from geometry.robot import ROBOT
from sim import robot as sim_robot
from sim.ik import ArmIK
from sim.sensing import WRIST_CAMERA
import toolbox.robot as tr
from toolbox.docs import toolbox_docs

model = sim_robot.build_robot_spec(visuals=False).compile()
tcp_site = float(model.site_pos[model.site(sim_robot.TCP_SITE).id][2])
ik = ArmIK()
tcp_ready_z = float(ik.fk(np.array(ROBOT.arm.ready))[2, 3])

cube = trimesh.creation.box((0.04, 0.04, 0.04))
def pickable(gap):
    step = 0.04 + gap
    records = [{"id": "c", "mesh": "cube", "pose": np.eye(4)}]
    for k, (dx, dy) in enumerate([(1, 0), (-1, 0), (0, 1), (0, -1)]):
        T = np.eye(4)
        T[:3, 3] = [dx * step, dy * step, 0.0]
        records.append({"id": f"n{k}", "mesh": "cube", "pose": T})
    for r in records:
        r["pose"] = np.array(r["pose"])
        r["pose"][:3, 3] += [0.5, 0.0, 0.02]
    return tr.Hand({"cube": cube}).can_pick(records, "c").ok

cubes = domains.load("cubes")
rule = next(s.text for s in rules_for(cubes, "plan") if s.check == "property.gripper_room")
ctx = build_context(cubes, (), toolbox_docs())
frozen = {d: f"def {d}(*args):\n    pass\n" for d in CODE_DEPS["plan"]}
request = build_request(ctx, "plan", 1, frozen=frozen)
prompt = "\n".join(b.text for b in (*request.system, *request.content) if hasattr(b, "text"))
print(json.dumps({
    "joints": len(sim_robot.ARM_JOINTS),
    "tcp_site": tcp_site,
    "tcp_ready_z": tcp_ready_z,
    "first_pickable_gap": next(g for g in (0.02, 0.025, 0.03, 0.035, 0.04, 0.045, 0.05) if pickable(g)),
    "finger_depth": tr.FINGER_DEPTH,
    "wrist_range": list(tr.WRIST_RANGE),
    "ik_wrist_range": model.jnt_range[model.joint(sim_robot.ARM_JOINTS[-1]).id].tolist(),
    "in_hand_noise": WRIST_CAMERA.position,
    "docs_state_depth": f"FINGER_DEPTH = {tr.FINGER_DEPTH}" in toolbox_docs(),
    "rule": rule,
    "prompt_names_robot": f"a {ROBOT.arm.full_name} arm with a {ROBOT.gripper.full_name}" in prompt,
    "robot_hash": robot_hash(),
}))
"""


def _probe(description: Path | None) -> dict:
    env = {k: v for k, v in os.environ.items() if k != ENV}
    if description is not None:
        env[ENV] = str(description)
    done = subprocess.run(
        [sys.executable, "-c", PROBE], cwd=REPO, env=env, capture_output=True, text=True,
        timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def _longer_fingers() -> dict:
    data = DEFAULT.to_json()
    segments = data["gripper"]["fingers"]["segments"]
    segments[0][2] = 0.030  # the fingertip reaches 30 mm out from its pad, not 17
    data["gripper"]["tcp_offset"] += 0.010
    data["gripper"]["name"] = "2F-85L"
    data["arm"]["full_name"] = "Franka FR3 (seam test)"
    data["arm"]["joint_ranges"][-1] = [-2.5, 2.5]
    data["wrist_camera"]["position_noise"] = 0.001
    return data


def test_every_consumer_follows_a_modified_description(tmp_path):
    path = tmp_path / "robot.json"
    path.write_text(json.dumps(_longer_fingers()))
    before, after = _probe(None), _probe(path)
    assert before["joints"] == after["joints"] == len(DEFAULT.arm.joints)
    # the simulator's tool frame and the IK built on it
    assert after["tcp_site"] == pytest.approx(before["tcp_site"] + 0.010, abs=1e-9)
    assert after["tcp_ready_z"] == pytest.approx(before["tcp_ready_z"] - 0.010, abs=2e-3)
    # the hand model: fatter fingertips need a wider gap between neighbours
    assert before["first_pickable_gap"] < after["first_pickable_gap"]
    # the toolbox's facts and the documentation the prompts show of them
    assert (before["finger_depth"], after["finger_depth"]) == (0.017, 0.030)
    assert after["wrist_range"] == after["ik_wrist_range"] == [-2.5, 2.5]
    assert before["ik_wrist_range"] == pytest.approx(list(DEFAULT.arm.wrist_range))
    # the executor's wrist camera
    assert (before["in_hand_noise"], after["in_hand_noise"]) == (0.0003, 0.001)
    assert before["docs_state_depth"] and after["docs_state_depth"]
    # a check's rule, the prompt, and what frozen sets were checked against
    assert "top-down 2F-85 grasp" in before["rule"]
    assert "top-down 2F-85L grasp" in after["rule"]
    assert before["prompt_names_robot"] and after["prompt_names_robot"]
    assert before["robot_hash"] != after["robot_hash"]


def test_the_description_reads_back_what_it_writes(tmp_path):
    path = tmp_path / "robot.json"
    path.write_text(json.dumps(DEFAULT.to_json()))
    again = load(path)
    assert again.to_json() == DEFAULT.to_json()
    assert again.gripper.fingers == DEFAULT.gripper.fingers
    np.testing.assert_array_equal(again.gripper.stroke.gap, DEFAULT.gripper.stroke.gap)
    assert isinstance(ROBOT, Robot) and ROBOT.to_json() == DEFAULT.to_json()


def test_a_bad_description_says_which_file_and_what(tmp_path):
    data = DEFAULT.to_json()
    del data["arm"]["park"]
    path = tmp_path / "robot.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"robot\.json is not a robot description .*park"):
        load(path)
    data = DEFAULT.to_json()
    data["arm"]["park"] = data["arm"]["park"][:6]
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="park has 6 values for 7 joints"):
        load(path)
