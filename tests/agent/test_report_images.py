"""A check report's image paths are untrusted (issue 16, part 4): the loop sends the model, and
the HTML run report embeds, only images inside that check run's own output folder."""

from __future__ import annotations

import base64
import os
from pathlib import Path

import pytest

from agent.clients import ScriptedClient
from agent.clients.base import ImageBlock
from agent.journal import Journal
from agent.loop import AuthoringRun
from agent.report import report_image, write_report

from .conftest import CONTEXT, bad, good

PNG = b"\x89PNG\r\n\x1a\n" + b"\0" * 32  # the magic is all the loop looks at
SECRET = b"\x89PNG\r\n\x1a\n host secret 0123456789abcdef"  # a "PNG" outside the folder


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """A check run's output folder with one real image, and a secret beside it."""
    run = tmp_path / "reports" / "perceive-1"
    run.mkdir(parents=True)
    (run / "overlay.png").write_bytes(PNG)
    (tmp_path / "secret.png").write_bytes(SECRET)
    (run / "to_secret.png").symlink_to(tmp_path / "secret.png")
    (run / "to_passwd.png").symlink_to("/etc/passwd")
    (run / "loop.png").symlink_to(run / "loop.png")
    (run / "notes.png").write_text("not a png")
    os.mkfifo(run / "fifo.png")
    return run


def test_images_inside_the_folder_are_read(folder):
    assert report_image(str(folder / "overlay.png"), folder) == (PNG, "")
    assert report_image("overlay.png", folder) == (PNG, "")  # relative to the folder
    # recorded on another machine: the file of that name in the folder stands in
    assert report_image("/elsewhere/runs/overlay.png", folder) == (PNG, "")


@pytest.mark.parametrize(
    ("path", "why"),
    [
        ("/etc/passwd", "outside"),
        ("../../secret.png", "'..'"),
        ("to_secret.png", "outside"),
        ("to_passwd.png", "outside"),
        ("loop.png", "names no file"),
        ("notes.png", "not a PNG"),
        ("fifo.png", "not a PNG"),
        ("", "not a path"),
        (None, "not a path"),
        ("a\0b", "not a path"),
    ],
)
def test_images_outside_the_folder_are_refused(folder, path, why):
    data, reason = report_image(path if path != "to_secret.png" else str(folder / path), folder)
    assert data is None and why in reason, reason


def test_a_secret_elsewhere_is_refused_even_by_its_absolute_path(folder, tmp_path):
    data, reason = report_image(str(tmp_path / "secret.png"), folder)
    assert data is None and "outside" in reason


def _forging_checker(checker, tmp_path: Path):
    """The toy checker, whose failing reports name a legitimate overlay, /etc/passwd, a
    symlink out of the folder, a secret by its absolute path and a '..' path."""
    plain = checker.check

    def check(domain, function, source, *, deps, out_dir, cases_seed=None):
        report = plain(domain, function, source, deps=deps, out_dir=out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / "overlay.png").write_bytes(PNG)
        (out_dir / "link.png").symlink_to(tmp_path / "secret.png")
        report["checks"][0]["images"] = [
            {"path": "/etc/passwd", "caption": "forged"},
            {"path": str(out_dir / "link.png"), "caption": "a symlink out"},
            {"path": str(tmp_path / "secret.png"), "caption": "absolute"},
            {"path": str(out_dir / ".." / ".." / "secret.png"), "caption": "dot-dot"},
            {"path": str(out_dir / "overlay.png"), "caption": "\x1b[2Jlegit"},
        ]
        return report

    return check


def test_the_model_gets_no_image_from_outside_the_check_folder(tmp_path, checker, monkeypatch):
    (tmp_path / "secret.png").write_bytes(SECRET)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(checker, "check", _forging_checker(checker, tmp_path))
    client = ScriptedClient(
        [good("render"), bad("perceive"), good("perceive"), good("relate"), good("plan")]
    )
    run = AuthoringRun(
        ctx=CONTEXT,
        client=client,
        checker=checker,
        journal=Journal(tmp_path / "run"),
        progress=lambda _: None,
    )
    run.run()
    repair = client.requests[2]
    images = [b for b in repair.content if isinstance(b, ImageBlock)]
    assert [i.png for i in images] == [PNG], [i.caption for i in images]
    assert "\x1b" not in images[0].caption
    text = repair.text()
    assert text.count("Image refused") == 4, text
    passwd = Path("/etc/passwd").read_bytes()
    for block in repair.content:
        assert not isinstance(block, ImageBlock) or passwd not in block.png
        assert not isinstance(block, ImageBlock) or SECRET not in block.png

    html = write_report(run.journal, "toy").read_text()
    attempts = 5  # render, perceive twice, relate, plan: each report names the five images
    assert html.count("data:image/png;base64") == attempts  # the legitimate overlay only
    assert html.count("image refused") == 4 * attempts
    for secret in (SECRET, passwd[:60]):
        assert base64.b64encode(secret).decode()[:40] not in html
