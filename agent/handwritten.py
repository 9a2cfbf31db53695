"""Package hand-written programs as a replay transcript, labelled as written by people.

A programs folder holds the final `render.py`, `perceive.py`, `relate.py`, `plan.py` and, in
`drafts/`, earlier failing versions `<function>_v<k>.py`. Packing runs the real authoring loop
with those files as the answers (drafts first, in version order, then the final version), the
real checks deciding each attempt, and records the exchange: the transcript then replays like a
model's, request hashes included, while its meta says plainly who wrote it.
"""

from __future__ import annotations

import re
from pathlib import Path

from agent.clients.base import Author, ModelRequest
from agent.clients.replay import RecordingClient
from agent.clients.scripted import ScriptedClient
from agent.errors import AgentError
from contracts.errors import UsageError
from contracts.functions import FUNCTIONS

PREAMBLE = (
    "Hand-written by {names} as the reference for this domain — part of a transcript written "
    "by people, not model output."
)


def program_sequence(folder: Path) -> dict[str, list[tuple[str, str]]]:
    """Per function: [(label, source)] — drafts in version order, then the final version."""
    out: dict[str, list[tuple[str, str]]] = {}
    for function in FUNCTIONS:
        final = folder / f"{function}.py"
        if not final.is_file():
            raise UsageError(f"{folder}: {final.name} is missing")
        drafts = []
        for p in (folder / "drafts").glob(f"{function}_v*.py"):
            m = re.fullmatch(rf"{function}_v(\d+)\.py", p.name)
            if m:
                drafts.append((int(m.group(1)), p))
        seq = [(f"drafts/{p.name}", p.read_text()) for _, p in sorted(drafts)]
        seq.append((final.name, final.read_text()))
        out[function] = seq
    return out


def response_text(source: str, names: str) -> str:
    return f"{PREAMBLE.format(names=names)}\n\n```python\n{source.rstrip()}\n```\n"


def packing_client(folder: Path, out: Path, domain: str, names: tuple[str, ...]) -> RecordingClient:
    sequence = program_sequence(folder)
    who = ", ".join(names)

    def answer(request: ModelRequest) -> str:
        seq = sequence[request.function]
        if request.attempt > len(seq):
            raise AgentError(
                f"{request.function}: the final version ({seq[-1][0]}) failed its checks; "
                "fix it before packing (rivet check)"
            )
        _, source = seq[request.attempt - 1]
        return response_text(source, who)

    calls = sum(len(s) for s in sequence.values())
    inner = ScriptedClient([answer] * calls, model="people (hand-written)")
    author = Author(
        kind="people",
        names=names,
        note="Hand-written reference programs (with earlier failing drafts), packaged by "
        "`rivet transcript pack`; not model output.",
    )
    return RecordingClient(inner, out, domain=domain, author=author)


def check_sequence_used(folder: Path, history) -> None:
    """Every draft must have failed and the final version passed, or the transcript lies."""
    sequence = program_sequence(folder)
    for function, seq in sequence.items():
        attempts = [a for a in history if a.function == function]
        if len(attempts) != len(seq) or not attempts[-1].passed:
            labels = [label for label, _ in seq]
            used = [(a.attempt, a.passed) for a in attempts]
            raise AgentError(
                f"{function}: expected the drafts to fail and the final version to pass "
                f"({labels}); got attempts {used} — a draft that passes is not a failing draft"
            )
