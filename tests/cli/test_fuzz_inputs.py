"""≥ 200 malformed observation folders and instance files: exit code 2 with a message, never a
traceback (`rivet solve`, `rivet scene render`), run in-process through the CLI entry point."""

from __future__ import annotations

import copy
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from rivet.cli import main
from sim.settle import physical_problems

FUZZ = settings(
    max_examples=110,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


@pytest.fixture(scope="module")
def observation(tmp_path_factory):
    import domains
    from artifacts.observations import write_observation
    from sim.observation import observe

    d = domains.load("cubes")
    inst = d.benchmark_instance(1, 1, physics=physical_problems)
    folder = tmp_path_factory.mktemp("obs") / "start"
    cam = d.camera("front")
    small = {**cam, "width": 320, "height": 180, "K": np.asarray(cam["K"]) * [[0.25], [0.25], [1]]}
    small["K"][0, 2], small["K"][1, 2] = (320 - 1) / 2, (180 - 1) / 2
    write_observation(observe(d, inst.start, small), folder)
    return folder


@pytest.fixture(scope="module")
def instance():
    import domains

    return domains.load("cubes").benchmark_instance(1, 1, physics=physical_problems).to_dict()


def _run(argv, capsys) -> tuple[int, str]:
    code = main(argv)
    err = capsys.readouterr().err
    return code, err


def _corrupt_observation(folder, kind: str, data) -> None:
    cam_path = folder / "camera.json"
    cam = json.loads(cam_path.read_text())
    if kind == "missing":
        (folder / data.draw(st.sampled_from(["rgb.png", "depth.png", "camera.json"]))).unlink()
    elif kind == "garbage_png":
        name = data.draw(st.sampled_from(["rgb.png", "depth.png"]))
        raw = (folder / name).read_bytes()
        cut = data.draw(st.integers(0, min(len(raw) - 1, 400)))
        (folder / name).write_bytes(raw[:cut] + data.draw(st.binary(max_size=64)))
    elif kind == "wrong_depth_type":
        Image.fromarray(np.zeros((cam["height"], cam["width"]), np.uint8)).save(
            folder / "depth.png"
        )
    elif kind == "wrong_size":
        w, h = data.draw(
            st.sampled_from(
                [(cam["width"] + 1, cam["height"]), (cam["width"], cam["height"] - 3), (8, 8)]
            )
        )
        name = data.draw(st.sampled_from(["rgb.png", "depth.png"]))
        arr = np.zeros((h, w, 3), np.uint8) if name == "rgb.png" else np.zeros((h, w), np.uint16)
        Image.fromarray(arr).save(folder / name)
    elif kind == "camera_json":
        choice = data.draw(
            st.sampled_from(
                ["not_json", "no_K", "bad_K", "neg_f", "scale", "nan", "pose", "extra", "list"]
            )
        )
        if choice == "not_json":
            cam_path.write_text(data.draw(st.sampled_from(["{", "", "nope", "[1,"])))
            return
        if choice == "no_K":
            del cam["K"]
        elif choice == "bad_K":
            cam["K"] = cam["K"][:2]
        elif choice == "neg_f":
            cam["K"][0][0] = -abs(cam["K"][0][0])
        elif choice == "scale":
            cam["depth_scale"] = data.draw(st.sampled_from([0, -1, "x"]))
        elif choice == "nan":
            cam["T_world_camera"][0][3] = float("nan")
        elif choice == "pose":
            cam["T_world_camera"][2][2] *= -1
        elif choice == "extra":
            cam["lens"] = "zed"
        else:
            cam = [cam]
        cam_path.write_text(json.dumps(cam))
    elif kind == "not_a_folder":
        shutil.rmtree(folder)
        folder.write_text("x")


@FUZZ
@given(
    st.data(),
    st.sampled_from(
        ["missing", "garbage_png", "wrong_depth_type", "wrong_size", "camera_json", "not_a_folder"]
    ),
)
def test_malformed_observation_folders_exit_2(tmp_path, observation, capsys, data, kind):
    bad = Path(tempfile.mkdtemp(dir=tmp_path)) / "start"
    shutil.copytree(observation, bad)
    _corrupt_observation(bad, kind, data)
    side = data.draw(st.sampled_from(["start", "goal"]))
    args = [str(bad), str(observation)] if side == "start" else [str(observation), str(bad)]
    code, err = _run(["solve", "cubes", *args], capsys)
    assert code == 2, err
    assert "Traceback" not in err and err.strip()


@FUZZ
@given(
    st.data(),
    st.sampled_from(
        [
            "not_json",
            "schema",
            "unknown_id",
            "improper",
            "duplicate",
            "penetrate",
            "domain",
            "float",
            "nan",
        ]
    ),
)
def test_malformed_instance_files_exit_2(tmp_path, instance, capsys, data, kind):
    inst = copy.deepcopy(instance)
    side = data.draw(st.sampled_from(["start", "goal"]))
    objs = inst[side]["objects"]
    k = data.draw(st.integers(0, len(objs) - 1))
    text = None
    if kind == "not_json":
        text = data.draw(st.sampled_from(["", "{", "[]", "null", "{'a': 1}"]))
    elif kind == "schema":
        what = data.draw(st.sampled_from(["no_goal", "extra", "pose_shape", "id_type"]))
        if what == "no_goal":
            del inst["goal"]
        elif what == "extra":
            objs[k]["colour"] = "red"
        elif what == "pose_shape":
            objs[k]["pose"] = objs[k]["pose"][:3]
        else:
            objs[k]["id"] = 7
    elif kind == "unknown_id":
        for s in ("start", "goal"):
            inst[s]["objects"][k]["id"] = "magenta"
    elif kind == "improper":
        for row in objs[k]["pose"][:3]:  # a reflection: det = -1
            row[0] = -row[0]
    elif kind == "duplicate":
        objs.append(copy.deepcopy(objs[k]))
    elif kind == "penetrate":
        j = (k + 1) % len(objs)
        objs[j]["pose"] = copy.deepcopy(objs[k]["pose"])
    elif kind == "domain":
        inst["domain"] = inst["start"]["domain"] = inst["goal"]["domain"] = data.draw(
            st.sampled_from(["cube", "lego", ""])
        )
    elif kind == "float":
        objs[k]["pose"][2][3] += data.draw(st.floats(0.05, 0.5))
    else:
        objs[k]["pose"][1][3] = float("nan")
    path = Path(tempfile.mkdtemp(dir=tmp_path)) / "instance.json"
    path.write_text(text if text is not None else json.dumps(inst))
    code, err = _run(["scene", "render", str(path), "--out", str(tmp_path / "out")], capsys)
    assert code == 2, err
    assert "Traceback" not in err and err.strip()
