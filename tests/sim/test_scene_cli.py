"""`rivet scene generate | render | show` on generated and hand-written instances."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

import domains
from artifacts.observations import read_observation
from geometry import resting_height
from rivet.cli import main


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
