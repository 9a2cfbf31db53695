"""Build the request for one function and attempt from the templates in `agent/prompts/`.

Layout (the stable prefix first, so it is cached across all calls of a run):
system: rules + representation + toolbox documentation            ← cache mark
user:   domain context (task, what the checks and the robot use,
        cameras, meshes) + reference images                        ← cache mark
        the function's task + what its draft is checked for (every rule of its checks)
        + the output contracts it consumes + frozen sources of its dependencies
        [repair: previous draft + check report + its images]

`python -m agent.prompt_sizes` prints each prompt's size (`agent.prompt_sizes`).
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from string import Template

from agent.clients.base import Block, ImageBlock, ModelRequest, TextBlock
from checks.rules import render
from contracts.functions import CODE_DEPS, CONTRACT_DEPS, SIGNATURES, authoring_order


@dataclass(frozen=True, kw_only=True)
class DomainContext:
    """What the prompts say about a domain."""

    domain: str
    task: str  # the task text τ (domains/<d>/task.md)
    cameras: str  # camera summary (Markdown)
    meshes: str  # mesh summary (Markdown)
    images: tuple[ImageBlock, ...] = ()
    toolbox_docs: str = ""
    # what the checks and the robot use (Markdown, `agent.context.domain_facts`)
    facts: str = ""
    # function → the rule of every check its drafts get (Markdown, `agent.context.function_rules`)
    rules: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class Feedback:
    """What the previous attempt produced, for a repair prompt."""

    draft: str
    report_markdown: str
    images: tuple[ImageBlock, ...] = field(default=())


def template(name: str) -> str:
    return (resources.files("agent") / "prompts" / name).read_text()


def templates_hash() -> str:
    """sha256 over every prompt template (recorded in the manifest)."""
    h = hashlib.sha256()
    for entry in sorted(
        resources.files("agent").joinpath("prompts").iterdir(), key=lambda p: p.name
    ):
        if entry.name.endswith(".md"):
            h.update(entry.name.encode() + b"\0" + entry.read_bytes() + b"\0")
    return h.hexdigest()


def frozen_use(function: str, dep: str) -> str:
    """How `function`'s draft may use its frozen dependency `dep`. Every session that loads
    `function`'s module holds the frozen programs before it in authoring order (the checks
    compose their sessions as the runtime does: `checks.calls.session_modules`), so `dep` is
    importable when it comes before `function` in that order."""
    order = authoring_order()
    if order.index(dep) < order.index(function):
        return f"already checked; importable as `from {dep} import {dep}`"
    return f"shown for reference, not to import: `{dep}` is written after `{function}`"


def build_request(
    ctx: DomainContext,
    function: str,
    attempt: int,
    *,
    frozen: dict[str, str],
    feedback: Feedback | None = None,
    max_attempts: int = 4,
    max_tokens: int = 16000,
) -> ModelRequest:
    system_text = "\n\n".join(
        [
            render(template("system.md"))[0],
            template("representation.md"),
            "# The toolbox\n\n" + ctx.toolbox_docs,
        ]
    )
    context = Template(template("context.md")).substitute(
        domain=ctx.domain,
        task=ctx.task.strip(),
        facts=("\n\n" + ctx.facts.strip()) if ctx.facts.strip() else "",
        cameras=ctx.cameras.strip(),
        meshes=ctx.meshes.strip(),
    )
    content: list[Block] = [TextBlock(text=context, cache=not ctx.images)]
    for i, img in enumerate(ctx.images):
        content.append(TextBlock(text=img.caption))
        content.append(ImageBlock(png=img.png, caption=img.caption))
        if i == len(ctx.images) - 1:
            content.append(TextBlock(text="(end of reference images)", cache=True))

    task = [template(f"{function}.md").strip()]
    task.append(f"Signature: `{SIGNATURES[function]}`")
    if ctx.rules.get(function):
        task.append(
            Template(template("checks.md")).substitute(rules=ctx.rules[function].strip()).strip()
        )
    for dep in CONTRACT_DEPS[function]:
        contract = template(f"contract_{dep}.md").strip()
        task.append(f"## Contract of `{dep}`\n\n`{SIGNATURES[dep]}`: {contract}")
    for dep in CODE_DEPS[function]:
        task.append(f"## Frozen `{dep}` ({frozen_use(function, dep)})")
        task[-1] += f"\n\n```python\n{frozen[dep].rstrip()}\n```"
    content.append(TextBlock(text="\n\n".join(task)))

    if feedback is not None:
        content.append(
            TextBlock(
                text=Template(template("repair.md")).substitute(
                    attempt=attempt - 1,
                    max_attempts=max_attempts,
                    previous_draft=feedback.draft.rstrip(),
                    report=feedback.report_markdown.strip(),
                )
            )
        )
        for img in feedback.images:
            # the checks' caption (sanitised by the loop) kept on one line: it is never a
            # Markdown block of its own, whatever it holds
            content.append(TextBlock(text=img.caption.replace("\n", " ")))
            content.append(img)
    return ModelRequest(
        function=function,
        attempt=attempt,
        system=(TextBlock(text=system_text, cache=True),),
        content=tuple(content),
        max_tokens=max_tokens,
    )


# -- prompt sizes ----------------------------------------------------------------------------


def request_size(request: ModelRequest) -> dict[str, int]:
    """Characters of a request (system, the domain prefix, the rest), its images, and its
    input tokens as the clients estimate them without a token count (characters / 3.5,
    width × height / 750 per image, `agent.clients.pricing`)."""
    from agent.clients.pricing import CHARS_PER_TOKEN, estimate_input_tokens, image_tokens

    system = sum(len(b.text) for b in request.system if isinstance(b, TextBlock))
    texts = [b for b in request.content if isinstance(b, TextBlock)]
    pictures = [b for b in request.content if isinstance(b, ImageBlock)]
    user = sum(len(b.text) for b in texts)
    return {
        "system_chars": system,
        "user_chars": user,
        "chars": system + user,
        "text_tokens": int((system + user) / CHARS_PER_TOKEN),
        "images": len(pictures),
        "image_tokens": sum(image_tokens(b.png) for b in pictures),
        "tokens": estimate_input_tokens(request),
    }
