"""Build the request for one function and attempt from the templates in `agent/prompts/`.

Layout (the stable prefix first, so it is cached across all calls of a run):
system: rules + representation + toolbox documentation            ← cache mark
user:   domain context (task, cameras, meshes) + reference images  ← cache mark
        the function's task + frozen sources of its dependencies
        [repair: previous draft + check report + its images]
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from importlib import resources
from string import Template

from agent.clients.base import Block, ImageBlock, ModelRequest, TextBlock
from contracts.functions import CODE_DEPS, CONTRACT_DEPS, SIGNATURES


@dataclass(frozen=True, kw_only=True)
class DomainContext:
    """What the prompts say about a domain."""

    domain: str
    task: str  # the task text τ (domains/<d>/task.md)
    cameras: str  # camera summary (Markdown)
    meshes: str  # mesh summary (Markdown)
    images: tuple[ImageBlock, ...] = ()
    toolbox_docs: str = ""


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
            template("system.md"),
            template("representation.md"),
            "# The toolbox\n\n" + ctx.toolbox_docs,
        ]
    )
    context = Template(template("context.md")).substitute(
        domain=ctx.domain,
        task=ctx.task.strip(),
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
    for dep in CODE_DEPS[function]:
        task.append(
            f"## Frozen `{dep}` (already checked; importable as `from {dep} import {dep}`)"
            f"\n\n```python\n{frozen[dep].rstrip()}\n```"
        )
    for dep in CONTRACT_DEPS[function]:
        task.append(f"## Contract of `{dep}`\n\n`{SIGNATURES[dep]}`: see the representation.")
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
            content.append(TextBlock(text=img.caption))
            content.append(img)
    return ModelRequest(
        function=function,
        attempt=attempt,
        system=(TextBlock(text=system_text, cache=True),),
        content=tuple(content),
        max_tokens=max_tokens,
    )
