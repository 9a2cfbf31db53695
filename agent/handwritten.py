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
from typing import Any

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


def packing_attempts(sequence: dict[str, list[tuple[str, str]]]) -> int:
    """The packing run's attempts per function: room for every draft and the final version."""
    return max(4, max(len(seq) for seq in sequence.values()))


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


def derivation_problems(
    domain: Any, artifacts_root: Path | None = None, *, prompts: bool = True
) -> list[str]:
    """Where `domain`'s committed transcript and frozen set are not what its people-written
    programs (`domains/<d>/programs/`, the only hand-edited source) produce: each problem in a
    line, [] when they are. Reads files only (no check runs): the transcript's answers are the
    programs (drafts, then the final version), each function's first request is the one the
    prompts build now (`prompts`: a replay would otherwise drift), the frozen files are the
    final versions, and the manifest was stamped against this checkout's contracts, toolbox
    and prompt templates. `make refreeze` (pack, then author) makes them so."""
    from agent.extract import extract_draft
    from agent.prompt import templates_hash
    from agent.transcript import Transcript
    from artifacts.errors import ArtifactError
    from artifacts.hashing import changed_since_checked
    from artifacts.store import verify

    folder = domain.root / "programs"
    if not folder.is_dir():
        return []  # a domain without people-written programs derives nothing
    problems: list[str] = []
    sequence = program_sequence(folder)
    try:
        transcript = Transcript.load(domain.reference_transcript)
    except Exception as e:  # a missing or unreadable transcript
        return [f"{domain.name}: the reference transcript cannot be read: {e}"]
    if transcript.written_by.kind != "people":
        problems.append(f"{domain.name}: the reference transcript is not labelled as people's")
    for function, seq in sequence.items():
        entries = sorted(
            (e for e in transcript.entries if e.function == function), key=lambda e: e.attempt
        )
        answers = [extract_draft(transcript.texts[e.file], function) for e in entries]
        wanted = [source for _, source in seq]
        if [a.rstrip() for a in answers] != [w.rstrip() for w in wanted]:
            labels = ", ".join(label for label, _ in seq)
            problems.append(
                f"{domain.name}: the transcript's {function} answers are not {labels} "
                f"({len(answers)} answers for {len(wanted)} files, or a file changed)"
            )
    if prompts:
        problems += _drifted_prompts(domain, transcript, sequence)
    try:
        manifest, sources = verify(domain.name, artifacts_root)
    except ArtifactError as e:
        return [*problems, f"{domain.name}: {e}"]
    for function, seq in sequence.items():
        if sources[function].rstrip() != seq[-1][1].rstrip():
            problems.append(
                f"{domain.name}: the frozen {function}.py is not programs/{function}.py"
            )
    if stale := changed_since_checked(manifest):
        problems.append(f"{domain.name}: the set was checked against other {', '.join(stale)}")
    if manifest.get("prompt_hash") != templates_hash():
        problems.append(f"{domain.name}: the set was authored from other prompt templates")
    return problems


def _drifted_prompts(domain: Any, transcript: Any, sequence: dict) -> list[str]:
    """The functions whose first recorded request is not the one the prompts build now, with
    the earlier functions' final versions frozen (as the packing run had them)."""
    from agent.context import build_context, reference_observations
    from agent.loop import DEFAULT_MAX_TOKENS
    from agent.prompt import build_request
    from contracts.functions import authoring_order
    from toolbox.docs import toolbox_docs

    ctx = build_context(domain, reference_observations(domain), toolbox_docs())
    max_attempts = packing_attempts(sequence)
    frozen: dict[str, str] = {}
    out = []
    for function in authoring_order():
        entry = transcript.find(function, 1)
        request = build_request(
            ctx, function, 1, frozen=frozen, max_attempts=max_attempts,
            max_tokens=DEFAULT_MAX_TOKENS,
        )  # fmt: skip
        if entry is not None and entry.request_hash != request.hash:
            out.append(
                f"{domain.name}: the prompt of {function} changed since the transcript was packed"
            )
        frozen[function] = sequence[function][-1][1]
    return out
