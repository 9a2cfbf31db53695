"""`rivet scene generate | render | show` on generated and hand-written instances."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import domains
from artifacts.observations import read_observation
from geometry import resting_height
from rivet.cli import main

DOCS_CAMERAS = Path(__file__).resolve().parents[2] / "docs" / "cameras"


def _hand_written(name: str) -> dict:
    """Two objects per scene, placed by hand at resting height, swapped between start and goal."""
    d = domains.load(name)
    a, b = d.objects[0], d.objects[1]

    def rec(o, x, y):
        pose = np.eye(4)
        pose[:3, 3] = (x, y, resting_height(d.parts[o.mesh], np.eye(3)))
        return {"id": o.id, "mesh": o.mesh, "pose": pose.tolist()}

    return {
        "domain": name,
        "start": {"domain": name, "objects": [rec(a, 0.45, -0.12), rec(b, 0.55, 0.12)]},
        "goal": {"domain": name, "objects": [rec(a, 0.55, 0.12), rec(b, 0.45, -0.12)]},
    }


@pytest.mark.parametrize("name", domains.names())
def test_render_a_hand_written_instance(name, tmp_path, capsys):
    path = tmp_path / "instance.json"
    path.write_text(json.dumps(_hand_written(name)))
    assert main(["scene", "render", str(path), "--out", str(tmp_path / "out")]) == 0
    for side in ("start", "goal"):
        obs = read_observation(tmp_path / "out" / side)
        assert obs["rgb"].shape == (720, 1280, 3)
        assert (obs["depth"] > 0).mean() > 0.9


def test_generate_draws_from_the_split_asked_for(tmp_path):
    import domains
    from domains.benchmark import dumps
    from sim.settle import physical_problems

    for split, name in (("dev", "seed4"), ("test", "test/seed4")):
        inst = tmp_path / f"{split}.json"
        assert (
            main(
                ["scene", "generate", "cubes", "--seed", "4", "--split", split, "--out", str(inst)]
            )
            == 0
        )
        drawn = json.loads(inst.read_text())
        expected = domains.load("cubes").generate(4, physics=physical_problems, split=split)
        assert drawn["name"] == name
        assert drawn == json.loads(dumps(expected.to_dict()))


def test_generate_then_render_and_show(tmp_path):
    inst = tmp_path / "i.json"
    assert main(["scene", "generate", "cubes", "--seed", "4", "--out", str(inst)]) == 0
    assert json.loads(inst.read_text())["order"]["steps"]
    assert (
        main(
            [
                "scene",
                "render",
                str(inst),
                "--out",
                str(tmp_path / "o"),
                "--camera",
                "view2",
                "--clean-depth",
            ]
        )
        == 0
    )
    assert (tmp_path / "o" / "goal" / "depth.png").exists()
    assert main(["scene", "show", "cubes/goal01_start1", "--out", str(tmp_path / "sheet.png")]) == 0
    with Image.open(tmp_path / "sheet.png") as im:
        w, h = im.size
    assert w == 3 * 640 and h > 2 * 360


def _refused(tmp_path, capsys, value) -> str:
    path = tmp_path / "bad.json"
    path.write_text(value if isinstance(value, str) else json.dumps(value))
    assert main(["scene", "render", str(path), "--out", str(tmp_path / "out")]) == 2
    return capsys.readouterr().err


def test_malformed_instances_are_refused(tmp_path, capsys):
    assert "not JSON" in _refused(tmp_path, capsys, "{")
    inst = _hand_written("cubes")
    inst["start"]["objects"][0]["pose"][0][0] = -1.0
    assert "start.objects[0].pose" in _refused(tmp_path, capsys, inst)
    inst = _hand_written("cubes")
    inst["goal"]["objects"][1]["id"] = "pink"
    err = _refused(tmp_path, capsys, inst)
    assert "pink" in err
    inst = _hand_written("tangram")
    inst["domain"] = inst["start"]["domain"] = inst["goal"]["domain"] = "cube"
    assert "unknown domain 'cube'; known: assembly, cubes, tangram" in _refused(
        tmp_path, capsys, inst
    )


def test_physically_invalid_instances_are_refused(tmp_path, capsys):
    inst = _hand_written("cubes")
    inst["goal"]["objects"][0]["pose"][2][3] += 0.05  # floating
    err = _refused(tmp_path, capsys, inst)
    assert "goal: object 'red': is not at rest" in err
    inst = _hand_written("cubes")
    inst["start"]["objects"][1]["pose"][0][3] = 0.46
    inst["start"]["objects"][1]["pose"][1][3] = -0.12
    err = _refused(tmp_path, capsys, inst)
    assert "start: object 'red': penetrates 'green'" in err


def test_unknown_domain_for_generate(capsys, tmp_path):
    assert (
        main(["scene", "generate", "cube", "--seed", "1", "--out", str(tmp_path / "x.json")]) == 2
    )
    assert "unknown domain 'cube'; known:" in capsys.readouterr().err


def test_render_from_a_camera_file_with_realism_and_truth(tmp_path, capsys):
    from sim.observation import load_camera
    from sim.realism import calibration_error

    out = tmp_path / "o"
    argv = ["scene", "render", "cubes/goal01_start1", "--out", str(out)]
    cam = str(DOCS_CAMERAS / "right_low.json")
    assert main([*argv, "--camera", cam, "--realism", "default", "--with-truth"]) == 0
    assert "calibration off by 2.0 mm / 0.20°" in capsys.readouterr().out
    true_cam = load_camera(cam)
    cals = []
    for side in ("start", "goal"):
        obs = read_observation(out / side)
        assert obs["rgb"].shape == (540, 960, 3)
        truth = load_camera(out / side / "true_camera.json")
        assert np.allclose(truth["T_world_camera"], true_cam["T_world_camera"])
        dt, dr = calibration_error(obs["camera"], truth)  # camera.json: the calibrated camera
        assert np.isclose(dt, 0.002, atol=1e-6) and np.isclose(np.degrees(dr), 0.2, atol=1e-4)
        cals.append(obs["camera"]["T_world_camera"])
    assert np.allclose(cals[0], cals[1])  # one camera, calibrated once
    # without --with-truth no true camera is written (and a stale one is removed)
    assert main([*argv, "--view", "view1"]) == 0
    for side in ("start", "goal"):
        assert not (out / side / "true_camera.json").exists()
        assert read_observation(out / side)["rgb"].shape == (720, 1280, 3)


def test_render_defaults_to_the_clean_protocol(tmp_path):
    from sim.observation import observe

    assert (
        main(["scene", "render", "tangram/goal01_start1", "--out", str(tmp_path), "--seed", "4"])
        == 0
    )
    d = domains.load("tangram")
    want = observe(d, d.benchmark()[0].start, "front", seed=4)
    got = read_observation(tmp_path / "start")
    assert np.array_equal(got["rgb"], want["rgb"])
    assert np.allclose(got["camera"]["T_world_camera"], want["camera"]["T_world_camera"])


def test_bad_cameras_are_refused(tmp_path, capsys):
    argv = ["scene", "render", "cubes/goal01_start1", "--out", str(tmp_path / "o")]
    good = json.loads((DOCS_CAMERAS / "right_low.json").read_text())

    def refused(*extra) -> str:
        assert main([*argv, *extra]) == 2
        return capsys.readouterr().err

    bad = tmp_path / "bad.json"
    bad.write_text("{")
    assert "bad.json: not JSON" in refused("--camera", str(bad))
    off = json.loads(json.dumps(good))
    off["K"][0][2] += 40
    bad.write_text(json.dumps(off))
    assert "principal point must be the image centre" in refused("--camera", str(bad))
    skew = json.loads(json.dumps(good))
    skew["K"][1][1] *= 1.02
    bad.write_text(json.dumps(skew))
    assert "square pixels" in refused("--camera", str(bad))
    assert "no such camera file" in refused("--camera", str(tmp_path / "none.json"))
    assert "neither a view of cubes" in refused("--camera", "top")
    assert "not both" in refused(
        "--view", "front", "--camera", str(DOCS_CAMERAS / "right_low.json")
    )
    with pytest.raises(SystemExit) as e:  # argparse choices
        main([*argv, "--realism", "dirty"])
    assert e.value.code == 2
    assert not (tmp_path / "o").exists()


def test_show_levels_and_camera_files(tmp_path):
    sheet = tmp_path / "levels.png"
    argv = ["scene", "show", "cubes/goal01_start1", "--out", str(sheet), "--side", "start"]
    levels = ["--realism", "clean", "--realism", "harsh"]
    cams = ["--camera", "front", "--camera", str(DOCS_CAMERAS / "left_high.json")]
    assert main([*argv, *levels, *cams, "--tile-width", "320", "--colors", "128"]) == 0
    with Image.open(sheet) as im:
        assert im.size == (2 * 320, 44 + 2 * 180) and im.mode == "P"
    assert (
        main([*argv, "--camera", "front", "--crop", "400,200,300,150", "--tile-width", "300"]) == 0
    )
    with Image.open(sheet) as im:
        assert im.size == (300, 44 + 150)
    assert main([*argv, "--crop", "1200,700,300,150"]) == 2
