"""`rivet solve` knows when it is lost: it writes what it perceived (records, relations, the
fit, an overlay per image) and refuses, exit 1, images its domain's objects do not explain —
here assembly's parts given to the cubes programs — instead of planning for cubes it made up.
The frozen programs run in a local sandbox session; the images come from the simulator."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import domains
from artifacts.observations import write_observation
from rivet.cli import main
from sim.observation import load_camera
from sim.trials import HONEST, observations

REPO = Path(__file__).resolve().parents[2]


def _solve(tmp_path, capsys, *, programs: str, images: str, camera: str = "front"):
    """`rivet solve PROGRAMS START GOAL --out OUT` on the first benchmark trial of the domain
    `images`, seen through `camera` (a view name or a camera file): (exit code, captured
    output, OUT)."""
    domain = domains.load(images)
    view = camera if camera in domain.cameras else load_camera(REPO / camera)
    folders = [
        str(write_observation(obs, tmp_path / images / side))
        for side, obs in zip(
            ("start", "goal"),
            observations(domain, domain.benchmark()[0], view, HONEST),
            strict=True,
        )
    ]
    out = tmp_path / "out"
    code = main(["solve", programs, *folders, "--sandbox", "local", "--out", str(out)])
    return code, capsys.readouterr(), out


@pytest.mark.slow
# a camera far from the table sees it with more depth noise: the table must not read as parts
@pytest.mark.parametrize("camera", ["front", "docs/cameras/envelope-1.json"])
def test_its_own_images_are_solved_and_what_was_seen_is_written(tmp_path, capsys, camera):
    code, captured, out = _solve(tmp_path, capsys, programs="cubes", images="cubes", camera=camera)
    assert code == 0, captured.err
    assert json.loads(captured.out)["status"] == "ok"
    for side in ("start", "goal"):
        seen = json.loads((out / f"{side}.json").read_text())
        assert len(seen["objects"]) == 6 and seen["relations"]["nodes"]
        assert seen["fit"]["ok"] and seen["fit"]["problems"] == []
        assert all(o["residual_m"] < 0.005 for o in seen["fit"]["objects"] if o["residual_m"])
        assert (out / f"{side}.png").stat().st_size > 10_000
    assert json.loads((out / "plan.json").read_text())["status"] == "ok"


@pytest.mark.slow
def test_another_domains_images_are_refused_naming_what_does_not_fit(tmp_path, capsys):
    code, captured, out = _solve(tmp_path, capsys, programs="cubes", images="assembly")
    assert code == 1
    assert captured.out == ""  # no plan
    assert "the images do not fit cubes, so no plan is given: start: " in captured.err
    assert "Traceback" not in captured.err
    fit = json.loads((out / "start.json").read_text())["fit"]
    assert not fit["ok"] and fit["problems"]
    assert (out / "start.png").is_file() and not (out / "plan.json").exists()
