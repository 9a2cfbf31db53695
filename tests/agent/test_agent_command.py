"""`--agent COMMAND`: the file protocol, its failures, and a whole authoring run through it."""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path

import pytest

from agent.clients import (
    AgentCommandClient,
    Budget,
    ImageBlock,
    ModelRequest,
    RecordingClient,
    ReplayClient,
    TextBlock,
)
from agent.clients.agent_command import command_name
from agent.errors import AgentCommandFailed, BudgetExceeded
from agent.journal import Journal
from agent.loop import AuthoringRun
from contracts.errors import UsageError
from contracts.functions import authoring_order

from .conftest import CONTEXT, bad, good

AGENT = Path(__file__).with_name("scripted_agent.py")
ORDER = authoring_order()
PNG = bytes.fromhex(
    "89504e470d0a1a0a0000000d4948445200000001000000010806000000"
    "1f15c4890000000d49444154789c6360000002000154a24f5d0000000049454e44ae426082"
)
REQUEST = ModelRequest(
    function="render",
    attempt=2,
    system=(TextBlock(text="the rules", cache=True),),
    content=(
        TextBlock(text="the task"),
        TextBlock(text="reference start: colour"),
        ImageBlock(png=PNG, caption="reference start: colour"),
        TextBlock(text="go"),
    ),
    max_tokens=1234,
)


def agent(tmp_path: Path, answers: Path, **kw) -> AgentCommandClient:
    return AgentCommandClient(
        f"{sys.executable} {AGENT} {answers}", work_dir=tmp_path / "agent", **kw
    )


def log(answers: Path) -> list[dict]:
    return [json.loads(line) for line in (answers / "log.jsonl").read_text().splitlines()]


@pytest.fixture
def answers(tmp_path) -> Path:
    d = tmp_path / "answers"
    d.mkdir()
    return d


def test_the_request_folder_holds_the_whole_prompt_and_its_images(tmp_path, answers):
    (answers / "render.md").write_text(good("render"))
    client = agent(tmp_path, answers)
    response = client.complete(REQUEST)
    assert response.text == good("render") and response.model == client.name
    folder = tmp_path / "agent" / "render-2"
    prompt = (folder / "prompt.md").read_text()
    assert "response.md" in prompt and "the rules" in prompt and "the task" in prompt
    assert "![reference start: colour](01-reference-start-colour.png)" in prompt
    assert (folder / "01-reference-start-colour.png").read_bytes() == PNG
    meta = json.loads((folder / "request.json").read_text())
    assert meta["max_tokens"] == 1234 and meta["request_hash"] == REQUEST.hash
    [entry] = log(answers)
    assert entry["cwd"] == str(folder.resolve()) and entry["request_dir"] == str(folder.resolve())
    assert entry["response_file"] == str((folder / "response.md").resolve())
    assert (entry["function"], entry["attempt"], entry["max_tokens"]) == ("render", 2, "1234")
    assert entry["images_present"] and entry["images"] == ["01-reference-start-colour.png"]


def test_the_author_is_the_command_name_not_its_arguments(tmp_path, answers):
    client = agent(tmp_path, answers)
    a = client.author.to_dict()
    assert a["kind"] == "model" and a["provider"] == "agent"
    assert a["model"] == f"{Path(sys.executable).name} scripted_agent.py"
    assert str(answers) not in json.dumps(a)
    assert command_name(["/usr/local/bin/claude", "-p", "--token", "x"]) == "claude"
    assert command_name(["python3", "-c", "print(1)"]) == "python3"
    assert command_name(["bash", "./my-agent.sh"]) == "bash my-agent.sh"


def test_non_zero_exit_is_a_clear_error_with_the_stderr_tail(tmp_path, answers):
    (answers / "render-2.exit").write_text("3")
    with pytest.raises(AgentCommandFailed, match="exited with status 3") as info:
        agent(tmp_path, answers).complete(REQUEST)
    assert "failing render-2 on purpose" in str(info.value)
    assert "render attempt 2" in str(info.value)


def test_no_response_file_is_a_clear_error(tmp_path, answers):
    with pytest.raises(AgentCommandFailed, match=r"exited 0 but wrote no response\.md"):
        agent(tmp_path, answers).complete(REQUEST)


def test_an_empty_response_is_a_clear_error(tmp_path, answers):
    (answers / "render.md").write_text("  \n")
    with pytest.raises(AgentCommandFailed, match=r"empty response\.md"):
        agent(tmp_path, answers).complete(REQUEST)


def test_a_hanging_command_is_killed_at_the_timeout(tmp_path, answers):
    (answers / "render-2.hang").write_text("")
    t0 = time.monotonic()
    with pytest.raises(AgentCommandFailed, match=r"did not finish within 1 s \(--agent-timeout\)"):
        agent(tmp_path, answers, timeout_s=1).complete(REQUEST)
    assert time.monotonic() - t0 < 10


def test_a_stale_response_from_an_earlier_try_is_never_read(tmp_path, answers):
    (answers / "render.md").write_text(good("render"))
    client = agent(tmp_path, answers)
    client.complete(REQUEST)
    (answers / "render.md").unlink()  # now the agent answers nothing
    with pytest.raises(AgentCommandFailed, match=r"wrote no response\.md"):
        client.complete(REQUEST)


def test_bad_commands_are_usage_errors(tmp_path):
    with pytest.raises(UsageError, match="not found"):
        AgentCommandClient("no-such-agent-program --x", work_dir=tmp_path)
    with pytest.raises(UsageError, match="empty"):
        AgentCommandClient("  ", work_dir=tmp_path)
    with pytest.raises(UsageError, match="No closing quotation"):
        AgentCommandClient("python 'x", work_dir=tmp_path)


def test_max_calls_applies(tmp_path, answers):
    (answers / "render.md").write_text(good("render"))
    client = agent(tmp_path, answers, budget=Budget(max_calls=1))
    client.complete(REQUEST)
    with pytest.raises(BudgetExceeded, match="max-calls 1"):
        client.complete(REQUEST)


def test_a_whole_run_through_the_agent_records_and_replays_strictly(tmp_path, answers, checker):
    """Render fails once and is repaired; the transcript replays byte for byte (strict)."""
    (answers / "render-1.md").write_text(bad("render"))
    for f in ORDER:
        (answers / f"{f}.md").write_text(good(f))
    ctx = dataclasses.replace(
        CONTEXT, images=(ImageBlock(png=PNG, caption="reference start: colour"),)
    )
    inner = agent(tmp_path, answers)
    rec = RecordingClient(inner, tmp_path / "transcript", domain="toy")
    frozen = AuthoringRun(
        ctx=ctx,
        client=rec,
        checker=checker,
        journal=Journal(tmp_path / "run"),
        progress=lambda _: None,
    ).run()
    assert set(frozen) == set(ORDER)
    asked = [(e["function"], e["attempt"]) for e in log(answers)]
    assert asked == [("render", 1), ("render", 2), ("perceive", 1), ("relate", 1), ("plan", 1)]
    assert all(e["images_present"] for e in log(answers))
    repair = (tmp_path / "agent" / "render-2" / "prompt.md").read_text()
    assert "return {'ok': False}" in repair  # the failed draft went back to the agent
    meta = json.loads((tmp_path / "transcript" / "meta.json").read_text())
    assert meta["written_by"]["provider"] == "agent"

    replay = ReplayClient(tmp_path / "transcript", strict=True)
    again = AuthoringRun(
        ctx=ctx,
        client=replay,
        checker=checker,
        journal=Journal(tmp_path / "replayed"),
        progress=lambda _: None,
    ).run()
    assert again == frozen
    assert len(log(answers)) == 5  # the replay asked the agent nothing
