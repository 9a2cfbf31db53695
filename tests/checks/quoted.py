"""How Markdown quotes text, for the tests of draft text in reports and prompts: which lines a
CommonMark reader takes as fenced code, and what of a line is left outside its code spans."""

from __future__ import annotations

import re

_FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})(.*)$")
_CODE_SPAN = re.compile(r"(?<!`)(`+)(?!`).*?(?<!`)\1(?!`)")


def split_fenced(text: str) -> tuple[list[str], list[str]]:
    """(the lines outside fenced code blocks, the lines inside them), by CommonMark's rules: a
    fence opens with three or more backticks or tildes (a backtick fence's info string holds
    no backtick) indented at most three spaces, and only a run of the same character at least
    as long, alone on its line, closes it; an unclosed fence runs to the end."""
    outside: list[str] = []
    inside: list[str] = []
    fence = ""
    for line in text.split("\n"):
        if fence:
            closing = _FENCE.match(line)
            run = closing.group(1) if closing else ""
            if (
                closing
                and run[0] == fence[0]
                and len(run) >= len(fence)
                and not closing.group(2).strip()
            ):
                fence = ""
            else:
                inside.append(line)
            continue
        opening = _FENCE.match(line)
        if opening and not (opening.group(1)[0] == "`" and "`" in opening.group(2)):
            fence = opening.group(1)
        else:
            outside.append(line)
    return outside, inside


def unquoted(text: str) -> list[str]:
    """The lines outside fenced code, each without its inline code spans: what a Markdown
    reader takes as the document's own text."""
    outside, _ = split_fenced(text)
    return [_CODE_SPAN.sub("", line) for line in outside]
