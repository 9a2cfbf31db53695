"""`rivet solve` knows when it is lost: it writes what it perceived (records, relations, the
fit, an overlay per image) and refuses, exit 1, images its domain's objects do not explain —
here assembly's parts given to the cubes programs — instead of planning for cubes it made up.
The frozen programs run in a local sandbox session; the images come from the simulator."""

from __future__ import annotations

import json

import pytest

import domains
from artifacts.observations import write_observation
from rivet.cli import main
from sim.trials import HONEST, observations


def _folders(tmp_path, domain_name: str) -> tuple[str, str]:
    domain = domains.load(domain_name)
    instance = domain.benchmark()[0]
    start, goal = observations(domain, instance, "front", HONEST)
    return (
        str(write_observation(start, tmp_path / domain_name / "start")),
        str(write_observation(goal, tmp_path / domain_name / "goal")),
    )


@pytest.mark.slow
def test_its_own_images_are_solved_and_what_was_seen_is_written(tmp_path, capsys):
    out = tmp_path / "solved"
    code = main(["solve", "cubes", *_folders(tmp_path, "cubes"), "--sandbox", "local",
                 "--out", str(out)])  # fmt: skip
    captured = capsys.readouterr()
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
    out = tmp_path / "lost"
    code = main(["solve", "cubes", *_folders(tmp_path, "assembly"), "--sandbox", "local",
                 "--out", str(out)])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 1
    assert captured.out == ""  # no plan
    assert "the images do not fit cubes, so no plan is given: start: " in captured.err
    assert "Traceback" not in captured.err
    fit = json.loads((out / "start.json").read_text())["fit"]
    assert not fit["ok"] and fit["problems"]
    assert (out / "start.png").is_file() and not (out / "plan.json").exists()
