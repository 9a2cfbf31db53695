"""The committed reference transcripts still answer today's prompts.

A first attempt's request depends only on the prompt templates, the toolbox documentation, the
domain context (task, cameras, meshes, reference images) and the frozen sources of the
function's dependencies, all of which are known without running a check. So a change to any of
them that would make `rivet author DOMAIN --strict` refuse the transcript fails here in seconds,
without Docker, and says what to do — instead of after minutes of replayed checks.
"""

from __future__ import annotations

import pytest

import domains
from agent import dag
from agent.context import build_context, reference_observations
from agent.extract import extract_draft
from agent.prompt import build_request
from agent.transcript import Transcript
from toolbox.docs import toolbox_docs


def _transcript_domains() -> list[str]:
    return [
        d
        for d in domains.names()
        if (domains.load(d).root / "transcripts" / "reference" / "meta.json").is_file()
    ]


@pytest.mark.parametrize("name", _transcript_domains())
def test_first_attempts_match_the_current_prompts(name):
    domain = domains.load(name)
    transcript = Transcript.load(domain.root / "transcripts" / "reference")
    ctx = build_context(domain, reference_observations(domain), toolbox_docs())
    frozen = {}
    for function in dag.FUNCTIONS:
        entries = [e for e in transcript.entries if e.function == function]
        assert entries, f"{name}: the transcript has no response for {function}"
        first = min(entries, key=lambda e: e.attempt)
        assert first.attempt == 1
        request = build_request(ctx, function, 1, frozen=frozen)
        assert request.hash == first.request_hash, (
            f"{name}: the prompt for {function} attempt 1 changed since the reference transcript "
            f"was packed; re-pack it (rivet transcript pack {name} domains/{name}/programs) and "
            f"re-freeze (make author DOMAIN={name})"
        )
        last = max(entries, key=lambda e: e.attempt)
        frozen[function] = extract_draft(transcript.texts[last.file], function)
