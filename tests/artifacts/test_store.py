"""Freezing, verification and the thin runtime on a small hand-made program set."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from artifacts import ArtifactError, build_manifest, freeze, load, unchecked_note, verify
from artifacts.hashing import REPO, checked_against

ARTIFACTS = REPO / "artifacts"

SOURCES = {
    "render": "def render(records, meshes, camera):\n    return {'n': len(records)}\n",
    "perceive": "from render import render\n\ndef perceive(observation, meshes, camera):\n"
    "    x = observation['depth'][0][0]\n"
    "    pose = [[1.0, 0, 0, x], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]]\n"
    "    return [{'id': 'a', 'mesh': 'm', 'pose': pose}]\n",
    "relate": "RELATIONS = {'on': 'rests on'}\n\ndef relate(records, meshes):\n"
    "    return {'directed': True, 'multigraph': True, 'graph': {}, "
    "'nodes': [{'id': r['id']} for r in records], 'edges': []}\n",
    "plan": "def plan(start, goal, meshes):\n"
    "    s = start['objects'][0]['pose']; g = goal['objects'][0]['pose']\n"
    "    return {'status': 'ok', 'steps': [] if s == g else [{'object': 'a', 'target_pose': g}]}\n",
}
AUTHOR = {"kind": "people", "names": ["RIVET tests"]}


@pytest.fixture
def root(tmp_path):
    manifest = build_manifest("toy", SOURCES, author=AUTHOR)
    assert freeze("toy", SOURCES, manifest, tmp_path)
    return tmp_path


def test_freeze_writes_stable_names_and_a_valid_manifest(root):
    names = sorted(p.name for p in (root / "toy").iterdir())
    assert names == ["manifest.json", "perceive.py", "plan.py", "relate.py", "render.py"]
    manifest, sources = verify("toy", root)
    assert sources == SOURCES
    assert manifest["functions"]["plan"]["depends_on"] == ["relate", "perceive"]


def test_refreezing_the_same_set_writes_nothing(root):
    before = (root / "toy" / "manifest.json").read_text()
    assert not freeze("toy", SOURCES, build_manifest("toy", SOURCES, author=AUTHOR), root)
    assert (root / "toy" / "manifest.json").read_text() == before


def test_a_changed_function_changes_the_set_hash(root):
    changed = {**SOURCES, "plan": SOURCES["plan"] + "# tweak\n"}
    m2 = build_manifest("toy", changed, author=AUTHOR)
    m1, _ = verify("toy", root)
    assert m2["set_hash"] != m1["set_hash"]
    assert freeze("toy", changed, m2, root)
    assert verify("toy", root)[1]["plan"].endswith("# tweak\n")


@pytest.mark.parametrize(
    "name", ["render.py", "perceive.py", "relate.py", "plan.py", "manifest.json"]
)
@pytest.mark.parametrize("where", [0, -2])
def test_one_tampered_byte_is_refused_naming_the_file(root, name, where):
    path = root / "toy" / name
    data = bytearray(path.read_bytes())
    data[where] = (data[where] + 1) % 256
    path.write_bytes(bytes(data))
    with pytest.raises(ArtifactError) as info:
        load("toy", root, meshes={})
    assert name in str(info.value) or "manifest" in str(info.value)


@pytest.mark.parametrize("name", ["render.py", "manifest.json"])
def test_a_missing_file_is_refused(root, name):
    (root / "toy" / name).unlink()
    with pytest.raises(ArtifactError, match=name.replace(".", r"\.")):
        verify("toy", root)


def _observation(x: float) -> dict:
    return {"rgb": [[[0, 0, 0]]], "depth": [[x]], "camera": {"width": 1, "height": 1}}


def test_the_runtime_runs_the_programs_in_a_sandbox_session(root):
    import sandbox

    system = load("toy", root, meshes={})
    with sandbox.open_executor("local", quiet=True) as executor, system.runner(executor) as run:
        plan = run.solve(_observation(0.0), _observation(0.1))
        assert set(run.timings) == {"perceive", "relate", "plan", "total", "round_trip"}
        assert run.cpu["perceive"] >= 0.0
        start, goal = run.last_states
    moved = [[1.0, 0, 0, 0.1], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]]
    assert plan == {"status": "ok", "steps": [{"object": "a", "target_pose": moved}]}
    assert start["relations"]["nodes"] == [{"id": "a"}] and goal["objects"][0]["pose"] == moved
    assert "render" not in sys.modules and "perceive" not in sys.modules  # not in this process


@pytest.mark.parametrize(
    ("plan_source", "message"),
    [
        ("def plan(start, goal, meshes):\n    raise RuntimeError('boom')\n", "raised RuntimeError"),
        ("import time\ndef plan(start, goal, meshes):\n    time.sleep(60)\n", "in time"),
        ("def plan(start, goal, meshes:\n", "do not load"),
    ],
    ids=["raises", "overruns", "does-not-load"],
)
def test_a_failing_frozen_program_is_a_program_failure(tmp_path, plan_source, message):
    import sandbox
    from artifacts.errors import ProgramFailed

    sources = {**SOURCES, "plan": plan_source}
    freeze("toy", sources, build_manifest("toy", sources, author=AUTHOR), tmp_path)
    system = load("toy", tmp_path, meshes={})
    with (
        sandbox.open_executor("local", quiet=True) as executor,
        pytest.raises(ProgramFailed, match=message),
        system.runner(executor, timeout_s=2.0) as run,
    ):
        run.solve(_observation(0.0), _observation(0.1))


def test_runtime_imports_neither_the_model_sdk_nor_docker(root):
    code = (
        "import sys; from artifacts import load; from pathlib import Path; "
        f"load('toy', Path({str(root)!r}), meshes={{}}); "
        "bad = [m for m in ('anthropic', 'docker') if m in sys.modules]; print(bad)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout.replace("'", '"')) == []


def test_the_same_set_checked_against_a_changed_toolbox_is_restamped(root):
    """A manifest says what its set passed its checks against; the same programs checked
    again against a changed toolbox get the new stamp and keep their evaluation."""
    path = root / "toy" / "manifest.json"
    old = json.loads(path.read_text())
    old["toolbox_hash"] = "0" * 64  # checked against some earlier toolbox
    path.write_text(json.dumps(old))
    (root / "toy" / "eval.json").write_text(json.dumps({"set_hash": old["set_hash"]}))
    assert "toolbox/ and geometry/" in (unchecked_note("toy", old) or "")

    fresh = build_manifest("toy", SOURCES, author=AUTHOR)
    assert fresh["set_hash"] == old["set_hash"]
    assert freeze("toy", SOURCES, fresh, root)
    manifest, _ = verify("toy", root)
    assert manifest["toolbox_hash"] == checked_against()["toolbox_hash"] != "0" * 64
    assert unchecked_note("toy", manifest) is None
    assert json.loads((root / "toy" / "eval.json").read_text())["set_hash"] == old["set_hash"]


@pytest.mark.parametrize("domain", sorted(p.parent.name for p in ARTIFACTS.glob("*/manifest.json")))
def test_committed_sets_were_checked_against_this_checkout(domain):
    """The committed manifests name the contracts and toolbox of this checkout: a change to
    either is followed by re-running the sets' checks (`rivet author D` replays them and
    re-stamps the set), so no frozen set claims checks it never passed."""
    manifest, _ = verify(domain)
    note = unchecked_note(domain, manifest)
    assert note is None, f"{note}\n(re-stamp: rivet author {domain} --strict)"
