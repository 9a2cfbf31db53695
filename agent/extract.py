"""Take the draft out of a model response: exactly one ```python block defining the function.

The draft is the one fence marked ```python (or ```py); fences in other languages (a diagram
in ```text, a shell line) are not read, and two ```python fences are an error. Only an answer
with no fence marked Python falls back to its unmarked fences (exactly one of them).

A malformed response is the model's mistake, not the run's: it becomes a check report of
category `interface` that goes back to the model like any other failure. A response cut off at
the output limit (`stop_reason: max_tokens`) that holds no usable draft is reported as such
(`truncated_error`, check `response_complete`), not as a missing code block.
"""

from __future__ import annotations

import ast
import re

_FENCE = re.compile(r"^```(?P<lang>[A-Za-z0-9_+-]*)[ \t]*\n(?P<body>.*?)^```[ \t]*$", re.M | re.S)


class DraftFormatError(Exception):
    """The response holds no usable draft; the message is written for the model."""


def extract_draft(text: str, function: str) -> str:
    """The source of the one ```python block in `text`, which must define `function`."""
    fences = list(_FENCE.finditer(text))
    blocks = [m for m in fences if m.group("lang").lower() in ("python", "py")]
    marked = bool(blocks)
    if not marked:
        blocks = [m for m in fences if not m.group("lang")]
    if not blocks:
        raise DraftFormatError(
            "your answer holds no ```python code block; answer with exactly one ```python block "
            f"holding the whole module that defines `{function}`"
        )
    if len(blocks) > 1:
        kind = "```python" if marked else "unmarked ```"
        raise DraftFormatError(
            f"your answer holds {len(blocks)} code blocks ({kind} fences); answer with exactly "
            f"one ```python block holding the whole module that defines `{function}` (fences in "
            "other languages, such as a ```text diagram, are not read)"
        )
    source = blocks[0].group("body")
    try:
        tree = ast.parse(source)
    except SyntaxError as e:
        raise DraftFormatError(
            f"the code block is not valid Python: line {e.lineno}: {e.msg}"
        ) from None
    defined = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    if function not in defined:
        names = ", ".join(sorted(defined)) or "none"
        raise DraftFormatError(
            f"the module must define a top-level function `{function}`; it defines: {names}"
        )
    return source if source.endswith("\n") else source + "\n"


def truncated_error(function: str, max_tokens: int, next_max_tokens: int) -> DraftFormatError:
    """What the model is told when its answer was cut off at `max_tokens`."""
    if next_max_tokens > max_tokens:
        room = f"the next attempt may use up to {next_max_tokens} tokens"
    else:
        room = f"{max_tokens} tokens is already the most an answer may use, so write less"
    return DraftFormatError(
        f"your answer was cut off: it reached the output limit of {max_tokens} tokens before "
        f"it ended (stop_reason: max_tokens), so it holds no complete draft; {room}. Answer "
        f"with exactly one complete ```python block holding the whole module that defines "
        f"`{function}`, with little prose around it"
    )


TRUNCATED_CHECK = "response_complete"


def format_error_report(
    domain: str, function: str, error: DraftFormatError, *, check: str = "response_format"
) -> dict:
    """A check report (contracts/schemas/check_report.schema.json) for a malformed response."""
    return {
        "schema_version": 1,
        "domain": domain,
        "function": function,
        "passed": False,
        "first_failure": check,
        "checks": [
            {
                "name": check,
                "category": "interface",
                "status": "failed",
                "message": str(error),
            }
        ],
    }
