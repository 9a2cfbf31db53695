"""An authoring run a reviewer can read end to end: a `--model` run against the wire-level fake
Anthropic API keeps every prompt it sent (text, and each image once by content hash), and its
`report.html` opens with who, what, when and how much, with each attempt's time, tokens, cost
and a link to its prompt."""

from __future__ import annotations

import hashlib
import re

import numpy as np
import pytest

from agent.clients import AnthropicClient, _http
from agent.journal import Journal
from agent.loop import AuthoringRun
from agent.report import write_report

from .conftest import CONTEXT, ToyChecker, bad, good
from .fake_model_server import FakeModelServer, anthropic_sse


class PictureChecker(ToyChecker):
    """The toy check, and a failing report carries an overlay image from its own folder."""

    def check(self, domain, function, source, *, deps, out_dir, cases_seed=None) -> dict:
        import cv2

        report = super().check(domain, function, source, deps=deps, out_dir=out_dir)
        if not report["passed"]:
            png = out_dir / "overlay.png"
            cv2.imwrite(str(png), np.full((24, 32, 3), (40, 90, 230), np.uint8))
            report["checks"][0]["images"] = [{"path": str(png), "caption": "what it got wrong"}]
            report["checks"][0]["message"] = "x" * 700 + " the end"
        return report


@pytest.fixture(scope="module")
def authored(tmp_path_factory):
    """A --model run of the toy domain against the fake Anthropic API: (journal, run folder)."""
    tmp_path = tmp_path_factory.mktemp("report")
    monkeypatch = pytest.MonkeyPatch()
    monkeypatch.setenv("ANTHROPIC_API_KEY", "sk-ant-test-not-a-key")
    answers = [good("render"), bad("perceive"), good("perceive"), good("relate"), good("plan")]
    journal = Journal(tmp_path / "run")
    with FakeModelServer() as server:
        server.script["messages"] += [anthropic_sse(a) for a in answers]
        client = AnthropicClient(
            base_url=server.url,
            retry=_http.RetryPolicy(initial_backoff_s=0.01),
            progress=lambda _: None,
        )
        AuthoringRun(
            ctx=CONTEXT,
            client=client,
            checker=PictureChecker(),
            journal=journal,
            progress=lambda _: None,
        ).run()
    monkeypatch.undo()
    return journal, tmp_path / "run"


def test_a_model_run_keeps_its_prompts_and_its_report_says_who_what_when_how_much(authored):
    journal, run = authored

    # every prompt, as sent: perceive's second one carries the failing check's image
    prompts = sorted(p.name for p in (run / "requests").glob("*.md"))
    assert prompts == ["perceive-1.md", "perceive-2.md", "plan-1.md", "relate-1.md", "render-1.md"]
    second = (run / "requests" / "perceive-2.md").read_text()
    image = re.search(r"!\[[^\]]*\]\(images/([0-9a-f]{64})\.png\)", second)
    assert image, second[-500:]
    stored = run / "requests" / "images" / f"{image.group(1)}.png"
    assert hashlib.sha256(stored.read_bytes()).hexdigest() == image.group(1)
    assert "Stack the blocks." in (run / "requests" / "render-1.md").read_text()

    page = write_report(journal, "RIVET authoring run — toy", set_hash="0123abcd").read_text()
    head = page[page.index("<table class=head>") : page.index("</table>")]
    for field, value in (
        ("domain", "toy"),
        ("author", "anthropic · claude-opus-5"),
        ("set hash", "0123abcd"),
        ("ended", "finished"),
    ):
        assert f"<th>{field}</th><td>{value}</td>" in head, head
    assert re.search(r"<th>commit</th><td>[0-9a-f]{12}</td>", head), head
    assert re.search(r"<th>date</th><td>20\d\d-\d\d-\d\d \d\d:\d\d:\d\d UTC</td>", head)
    assert re.search(r"<th>tokens</th><td>\d+ input, \d+ output", head)
    assert "<th>cost</th><td>$" in head
    # per attempt: time, tokens, cost and the prompt's link
    attempt = re.search(r"attempt 2: .*?</h3><p class=meta>(.*?)</p>", page, re.S)
    assert attempt and re.search(r"\d+ s · \d+ in, \d+ out, \d+ cache-read tokens; \$", attempt[1])
    assert '<a href="requests/perceive-2.md">the prompt</a>' in attempt[1]
    # a long message is whole (folded), never cut
    assert "x" * 700 + " the end" in page


def test_the_report_renders_in_a_real_browser_and_fits_the_page(authored, tmp_path):
    """Headless Chromium (the system package `make system` installs) lays the page out: the
    header and every attempt are there, nothing is wider than the window (the side-by-side diff
    included), and a screenshot is kept beside the test's files for a person to look at."""
    import shutil
    import subprocess

    journal, run = authored
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    assert browser, "chromium is missing: `make system` (scripts/bootstrap-system.sh) installs it"
    page = write_report(journal, "RIVET authoring run — toy", set_hash="0123abcd")
    probe = run / "probe.html"
    probe.write_text(
        page.read_text()
        + "<script>document.body.dataset.overflow = String(document.documentElement.scrollWidth"
        " > window.innerWidth); document.body.dataset.attempts = String(document.querySelectorAll"
        "('h3').length); document.body.dataset.head = String(document.querySelectorAll("
        "'table.head tr').length);</script>"
    )
    common = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--window-size=1100,1400"]
    dom = subprocess.run(
        [*common, "--dump-dom", probe.as_uri()], capture_output=True, text=True, timeout=120
    )
    assert dom.returncode == 0, dom.stderr[-2000:]
    body = re.search(r"<body([^>]*)>", dom.stdout)
    assert body, dom.stdout[:2000]
    assert 'data-overflow="false"' in body[1], body[1]
    assert 'data-attempts="5"' in body[1] and 'data-head="10"' in body[1], body[1]
    shot = tmp_path / "report.png"
    subprocess.run([*common, f"--screenshot={shot}", page.as_uri()], capture_output=True,
                   timeout=120, check=True)  # fmt: skip
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 20_000
