"""`pytest --rivet-artifacts DIR`, as a user's CI runs it: one item per artifact set's integrity
and per frozen program's check suite; a tampered file fails its set's integrity item."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def _pytest(root: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-p",
            "no:cacheprovider",
            "--rivet-artifacts",
            str(root),
            *args,
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
    )


def test_items_per_set_and_function_and_keyword_selection(tmp_path):
    shutil.copytree(REPO / "artifacts" / "cubes", tmp_path / "cubes")
    manifest = str(tmp_path / "cubes" / "manifest.json")
    listed = _pytest(tmp_path, "--collect-only", "-q", manifest)
    assert listed.returncode == 0, listed.stdout + listed.stderr
    for item in ("integrity", "render", "perceive", "relate", "plan"):
        assert f"manifest.json::cubes::{item}" in listed.stdout
    ok = _pytest(tmp_path, "-q", "-k", "integrity", manifest)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert "1 passed" in ok.stdout


def test_a_tampered_file_fails_the_integrity_item_naming_it(tmp_path):
    shutil.copytree(REPO / "artifacts" / "cubes", tmp_path / "cubes")
    plan = tmp_path / "cubes" / "plan.py"
    data = bytearray(plan.read_bytes())
    data[-2] ^= 0x01
    plan.write_bytes(bytes(data))
    bad = _pytest(tmp_path, "-q", "-k", "integrity", str(tmp_path / "cubes" / "manifest.json"))
    assert bad.returncode == 1, bad.stdout + bad.stderr
    assert "plan.py" in bad.stdout


def test_pointed_at_a_folder_it_collects_only_its_sets(tmp_path):
    """Without paths, only the artifact suites; with paths, those as well (as `make test`)."""
    shutil.copytree(REPO / "artifacts" / "cubes", tmp_path / "cubes")
    alone = _pytest(tmp_path, "--collect-only", "-q")
    assert alone.returncode == 0, alone.stdout + alone.stderr
    items = [line for line in alone.stdout.splitlines() if "::" in line]
    assert len(items) == 5 and all("manifest.json::cubes::" in i for i in items), items
    beside = _pytest(tmp_path, "--collect-only", "-q", "tests/test_import_graph.py")
    assert "tests/test_import_graph.py::" in beside.stdout
    assert "manifest.json::cubes::integrity" in beside.stdout


def test_an_integrity_failure_is_one_readable_line(tmp_path):
    shutil.copytree(REPO / "artifacts" / "cubes", tmp_path / "cubes")
    (tmp_path / "cubes" / "relate.py").write_text("# replaced\n")
    bad = _pytest(tmp_path, "-q", "-k", "integrity")
    assert bad.returncode == 1
    assert "refusing to load a modified artifact" in bad.stdout
    assert "Traceback" not in bad.stdout and "raise ArtifactError" not in bad.stdout, bad.stdout


def test_a_failing_suite_leaves_its_case_images_for_ci_and_a_passing_one_none(tmp_path):
    from artifacts import build_manifest, freeze
    from artifacts.runtime import read_programs

    sources = read_programs(REPO / "artifacts" / "cubes")
    sources["render"] += (
        "\n\n_right = render\n\n\ndef render(records, meshes, camera):  # 2 cm too deep\n"
        "    out = dict(_right(records, meshes, camera))\n"
        "    out['depth'] = out['depth'] + 0.02 * (out['depth'] > 0)\n"
        "    return out\n"
    )
    manifest = build_manifest("cubes", sources, author={"kind": "people", "names": ["tests"]})
    freeze("cubes", sources, manifest, root=tmp_path / "sets")
    images = tmp_path / "images"
    bad = _pytest(tmp_path / "sets", "-q", "-k", "render", "--rivet-sandbox", "local",
                  "--rivet-images", str(images))  # fmt: skip
    assert bad.returncode == 1, bad.stdout + bad.stderr
    pictures = sorted((images / "cubes" / "render").rglob("*.png"))
    assert pictures, bad.stdout
    assert f"images of the failing cases ({len(pictures)}), under {images}/cubes/render/" in (
        bad.stdout
    )
    assert str(pictures[0]) in bad.stdout
    ok = _pytest(REPO / "artifacts", "-q", "-k", "cubes and render", "--rivet-sandbox", "local",
                 "--rivet-images", str(images))  # fmt: skip
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert not (images / "cubes" / "render").exists()  # passed: nothing left behind
