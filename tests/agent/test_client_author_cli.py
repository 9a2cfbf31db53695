"""`rivet author` with the new clients, end to end through the command line (in process): the
domain context, the toolbox docs and the sandboxed check suites are replaced by the toy ones
of conftest.py; the clients, the loop, the journal, the ledger and freezing are real."""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import pytest

from contracts.functions import authoring_order
from rivet.cli import main

from .conftest import CONTEXT, ToyChecker, good
from .fake_model_server import FakeModelServer, anthropic_sse, closed_port_url

AGENT = Path(__file__).with_name("scripted_agent.py")
ORDER = authoring_order()


class ToySuite(ToyChecker):
    def __init__(self, *, sandbox: str = "docker", thorough: bool = False) -> None:
        super().__init__()

    def close(self) -> None:
        pass


@pytest.fixture(autouse=True)
def _toy_domain(monkeypatch):
    import agent.checking
    import agent.context
    import toolbox.docs

    monkeypatch.setattr(
        agent.context,
        "build_context",
        lambda domain, obs=(), docs="": dataclasses.replace(CONTEXT, domain=domain.name),
    )
    monkeypatch.setattr(agent.context, "reference_observations", lambda domain: [])
    monkeypatch.setattr(toolbox.docs, "toolbox_docs", lambda: "(toolbox docs)")
    monkeypatch.setattr(agent.checking, "SuiteChecker", ToySuite)
    monkeypatch.setenv("ANTHROPIC_API_KEY", "sk-ant-test-not-a-key")


def author(tmp_path: Path, *args: str) -> int:
    return main(
        [
            "author",
            "cubes",
            "--runs-dir",
            str(tmp_path / "runs"),
            "--artifacts",
            str(tmp_path / "art"),
            "--gate-trials",
            "0",  # the toy programs solve no real task: these tests are about the clients
            *args,
        ]
    )


def test_an_unreachable_api_is_one_clear_message(tmp_path, capsys):
    url = closed_port_url()
    assert author(tmp_path, "--model", "claude-opus-5", "--base-url", url, "--max-usd", "5") == 1
    err = capsys.readouterr().err
    assert err.count(f"cannot reach the Anthropic API at {url}") == 1, err
    assert "token count failed" not in err and "Connection error." not in err
    assert "authoring failed" not in err and "report: " in err


def test_a_whole_run_by_an_agent_command_is_frozen_and_names_it(tmp_path, capsys):
    answers = tmp_path / "answers"
    answers.mkdir()
    for f in ORDER:
        (answers / f"{f}.md").write_text(good(f))
    command = f"{sys.executable} {AGENT} {answers}"
    assert author(tmp_path, "--agent", command, "--agent-timeout", "60") == 0, (
        capsys.readouterr().err
    )
    manifest = json.loads((tmp_path / "art" / "cubes" / "manifest.json").read_text())
    assert manifest["author"]["kind"] == "model" and manifest["author"]["provider"] == "agent"
    assert manifest["author"]["model"] == f"{Path(sys.executable).name} scripted_agent.py"
    from contracts import validate

    validate("manifest", manifest)
    [run] = (tmp_path / "runs" / "cubes").iterdir()
    assert sorted(p.name for p in (run / "agent").iterdir()) == sorted(f"{f}-1" for f in ORDER)
    meta = json.loads((run / "transcript" / "meta.json").read_text())
    assert meta["written_by"]["provider"] == "agent" and len(meta["responses"]) == 4


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--agent", "true", "--max-usd", "5"], "--max-usd cannot be enforced with --agent"),
        (["--agent", "true", "--thinking", "2048"], "--thinking: only with --model"),
        (
            ["--model", "openai:qwen", "--base-url", "http://127.0.0.1:9/v1", "--max-usd", "5"],
            "pass --price IN,OUT",
        ),
        (
            ["--model", "openai:qwen", "--base-url", "http://127.0.0.1:9/v1", "--thinking", "2048"],
            "--thinking is for Claude",
        ),
        (["--base-url", "http://127.0.0.1:9"], "--base-url: only with --model"),
        (["--model", "claude-opus-5", "--price", "x"], "--price 'x'"),
        (
            ["--model", "gpt-4o"],
            "not a Claude model. An OpenAI-compatible model is --model openai:gpt-4o",
        ),
    ],
)
def test_option_mistakes_are_usage_errors(tmp_path, capsys, args, message):
    assert author(tmp_path, *args) == 2
    assert message in capsys.readouterr().err


def _worst(server_count: int) -> float:
    """The worst case of one call when the token count dominates: input all written to the
    cache at $5/M × 1.25, and 16000 output tokens at $25/M."""
    return server_count * 5 * 1.25 / 1e6 + 16000 * 25 / 1e6


COST = (100 * 5 + 50 * 25 + 1000 * 5 * 1.25 + 2000 * 5 * 0.1) / 1e6  # one fake call: $0.009


def test_the_dollar_budget_spans_runs(tmp_path, capsys):
    with FakeModelServer(count_tokens=100_000) as server:
        server.script["messages"] += [anthropic_sse(good(f)) for f in ORDER] * 2
        worst = _worst(100_000)
        # run 1's last call fits (3 calls spent), run 2's first call fits, its second does not
        limit = 5 * COST + worst - 0.0005
        code = author(
            tmp_path,
            "--model",
            "claude-opus-5",
            "--base-url",
            server.url,
            "--runs",
            "2",
            "--max-usd",
            repr(limit),
        )
        out, err = capsys.readouterr()
        assert code == 1
        assert "1/2 runs produced a complete checked set" in out
        assert "could cost up to" in err
        assert len(server.calls("messages")) == 4 + 1


def test_resume_starts_from_what_the_run_spent(tmp_path, capsys):
    worst = _worst(100_000)
    limit = 2 * COST + worst - 0.0005  # two calls, then refused
    with FakeModelServer(count_tokens=100_000) as server:
        server.script["messages"] += [anthropic_sse(good(f)) for f in ORDER]
        base = ["--model", "claude-opus-5", "--base-url", server.url, "--max-usd"]
        assert author(tmp_path, *base, repr(limit)) == 1
        assert len(server.calls("messages")) == 2
        capsys.readouterr()
        # resumed with the same budget: the journal's $0.018 counts, so relate is refused again
        assert author(tmp_path, "--resume", *base, repr(limit)) == 1
        err = capsys.readouterr().err
        assert "this run has spent $0.02 in 2 calls so far" in err and "could cost up to" in err
        assert len(server.calls("messages")) == 2
        # with room for the remaining two calls it finishes, asking only for those
        assert author(tmp_path, "--resume", *base, repr(limit + 2 * COST + 0.001)) == 0
        assert len(server.calls("messages")) == 4
        [run] = (tmp_path / "runs" / "cubes").iterdir()
        events = [json.loads(line) for line in (run / "journal.jsonl").read_text().splitlines()]
        assert sum(e["event"] == "refused" for e in events) == 2


@pytest.mark.parametrize(
    ("args", "unset", "message"),
    [
        (["--replay", "/nowhere"], None, "no transcript at /nowhere"),
        (["--model", "claude-opus-5"], "ANTHROPIC_API_KEY", "ANTHROPIC_API_KEY is not set"),
        (["--model", "openai:gpt-4o"], "OPENAI_API_KEY", "OPENAI_API_KEY is not set"),
        (["--model", "gpt-4o"], None, "--model openai:gpt-4o"),
    ],
)
def test_nothing_is_created_before_the_sources_are_checked(
    tmp_path, capsys, monkeypatch, args, unset, message
):
    if unset:
        monkeypatch.delenv(unset, raising=False)
        monkeypatch.delenv("ANTHROPIC_AUTH_TOKEN", raising=False)
        monkeypatch.delenv("OPENAI_BASE_URL", raising=False)
    assert author(tmp_path, *args) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()  # no empty run for a study to count as failed
