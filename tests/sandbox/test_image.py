"""The image recipe: pins follow uv.lock, the tag follows the inputs, the base is found offline."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from sandbox import image


def test_requirements_match_uv_lock():
    assert image.REQUIREMENTS.read_text() == image.lock_requirements(), (
        "sandbox/requirements.txt is stale: run `python -m sandbox.image lock`"
    )


def test_requirements_pin_every_root_package_with_one_wheel():
    reqs = image.read_requirements()
    names = [name for name, *_ in reqs]
    assert set(image.ROOT_PACKAGES) <= set(names) and len(names) == len(set(names))
    for name, _, digest, url in reqs:
        assert re.fullmatch(r"[0-9a-f]{64}", digest) and url.startswith("https://")
        assert url.endswith(".whl") and ("x86_64" in url or "none-any" in url), name
    pyopengl = next(version for name, version, *_ in reqs if name == "pyopengl")
    assert tuple(int(p) for p in pyopengl.split(".")[:3]) >= (3, 1, 7)  # the EGL override


def test_tag_is_a_hash_of_the_inputs_and_only_of_them():
    inputs = image.build_inputs()
    assert {"Dockerfile", "requirements.txt", "lib/sandbox/__init__.py"} <= set(inputs)
    assert "lib/sandbox/harness/server.py" in inputs and "lib/contracts/__init__.py" in inputs
    assert any(p.startswith("lib/toolbox/") for p in inputs)
    assert not any("__pycache__" in p or p.endswith(".pyc") for p in inputs)
    digest = image.image_hash(inputs)
    assert image.image_hash(dict(inputs)) == digest
    assert image.image_hash(dict(reversed(list(inputs.items())))) == digest
    for changed in ("Dockerfile", "lib/sandbox/harness/child.py", "lib/contracts/__init__.py"):
        assert image.image_hash({**inputs, changed: inputs[changed] + b"\n"}) != digest
    assert re.fullmatch(r"rivet-sandbox:[0-9a-f]{12}", image.image_tag())


def test_dockerfile_defaults_to_the_public_base_and_runs_unprivileged():
    text = (image.SANDBOX_DIR / "Dockerfile").read_text()
    assert "ARG BASE=python:3.11-slim-bookworm" in text
    assert "--no-index" in text and "--require-hashes" in text
    assert re.search(r"^USER 10001:10001$", text, re.M)


def test_build_base_script_is_valid_bash():
    script = image.SANDBOX_DIR / "build_base.sh"
    subprocess.run(["bash", "-n", str(script)], check=True)
    text = script.read_text()
    assert "debootstrap --variant=minbase" in text and "docker import" in text


class FakeImages:
    def __init__(self, present: set[str], pull_ok: bool) -> None:
        self.present, self.pull_ok, self.pulled = present, pull_ok, []

    def get(self, ref: str):
        import docker

        if ref not in self.present:
            raise docker.errors.ImageNotFound(ref)
        return ref

    def pull(self, repo: str, tag: str | None = None):
        self.pulled.append(f"{repo}:{tag}" if tag else repo)
        if not self.pull_ok:
            raise RuntimeError("dial tcp: lookup registry-1.docker.io: no such host")
        self.present.add(self.pulled[-1])


class FakeClient:
    def __init__(self, present: set[str], pull_ok: bool) -> None:
        self.images = FakeImages(present, pull_ok)


@pytest.mark.parametrize(
    ("present", "pull_ok", "base", "built"),
    [
        ({image.ONLINE_BASE}, False, image.ONLINE_BASE, False),
        (set(), True, image.ONLINE_BASE, False),
        ({image.OFFLINE_BASE}, False, image.OFFLINE_BASE, False),
        (set(), False, image.OFFLINE_BASE, True),
    ],
)
def test_base_resolution_falls_back_to_the_offline_base(monkeypatch, present, pull_ok, base, built):
    monkeypatch.delenv("RIVET_SANDBOX_BASE", raising=False)
    calls = []
    monkeypatch.setattr(image, "build_base", lambda: calls.append("built"))
    assert image.resolve_base(FakeClient(set(present), pull_ok)) == base
    assert bool(calls) == built


def test_a_failing_base_build_is_an_error(monkeypatch, tmp_path: Path):
    fake = tmp_path / "build_base.sh"
    fake.write_text("exit 3\n")
    monkeypatch.setattr(image, "SANDBOX_DIR", tmp_path)
    with pytest.raises(image.ImageBuildError, match="exit 3"):
        image.build_base()
