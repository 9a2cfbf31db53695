"""The HTML report of an authoring run: per function, its attempts, the code diff between
attempts, the check results, the overlay images and the usage. One self-contained file.

A check report's image paths are data, not trust: an image is read (here, and by the loop for
the model) only when its path, symlinks resolved, lies inside that check run's own output
folder and the file is a PNG of sane size (`report_image`); anything else is refused, said
so where the image would have been, and never read.

Every string of a check report, the feedback the model was sent and the drafts themselves are
text a draft (or the model) produced: each is sanitised (`checks.report.sanitise_text`:
invisible and reordering characters such as bidi overrides shown as escapes) and then
HTML-escaped before it is written, attributes quoted — never markup of its own.
"""

from __future__ import annotations

import base64
import difflib
import html
import json
import os
import stat
from pathlib import Path

from agent.journal import Journal
from checks.report import sanitise_text
from contracts.functions import FUNCTIONS, authoring_order

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
MAX_IMAGE_BYTES = 16 << 20  # [bytes] an overlay PNG is a few hundred KiB

_CSS = """
body{font:14px/1.45 system-ui,sans-serif;margin:2em auto;max-width:1100px;color:#222}
h1{font-size:22px}h2{font-size:18px;margin-top:2em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;margin:.5em 0;max-width:100%}
td,th{border:1px solid #ddd;padding:3px 8px;text-align:left}td:last-child{overflow-wrap:anywhere}
.passed{color:#1a7f37}.failed,.error{color:#cf222e}.skipped{color:#888}
details{margin:.5em 0}pre{background:#f6f8fa;padding:8px;overflow:auto;font-size:12px;
white-space:pre-wrap;overflow-wrap:anywhere}
table.diff{font:12px monospace;table-layout:fixed;width:100%}
table.diff td{word-break:break-all;white-space:pre-wrap;vertical-align:top}
table.diff col.diff_next,table.diff td.diff_next{width:1.5em}table.diff .diff_header{width:3em}
.diff_add{background:#e6ffec}.diff_sub{background:#ffebe9}.diff_chg{background:#fff5b1}
table.head th{width:9em;background:#f6f8fa}
img{max-width:100%;border:1px solid #ddd;margin:4px 0}
"""


def report_image(path: object, folder: Path) -> tuple[bytes | None, str]:
    """The bytes of the image a check report names, or (None, why it was refused).

    `folder` is the check run's own output folder (where its checks wrote their images). The
    path may be absolute or relative (to the working directory the checks ran in, or to the
    folder; a file of the same name in the folder stands in for one recorded elsewhere); it
    is refused when it holds '..', when it resolves (symlinks followed) outside `folder`, or
    when what it names is not a regular PNG file of at most `MAX_IMAGE_BYTES`.
    """
    if not isinstance(path, str) or not path or "\0" in path:
        return None, "the image path is not a path"
    named = Path(path)
    if ".." in named.parts:
        return None, f"the image path {sanitise_text(path)[:200]!r} climbs out with '..'"
    try:
        root = folder.resolve(strict=True)
    except OSError:
        return None, "the check run's output folder does not exist"
    where = [named] if named.is_absolute() else [Path.cwd() / named, folder / named]
    why = f"the image path {sanitise_text(path)[:200]!r} names no file in the check run's folder"
    for candidate in [*where, folder / named.name]:
        try:
            real = candidate.resolve(strict=True)
        except (OSError, RuntimeError):  # missing, or a symlink loop
            continue
        if not real.is_relative_to(root):
            why = (
                f"the image path {sanitise_text(path)[:200]!r} leads outside the check run's folder"
            )
            continue
        try:
            fd = os.open(real, os.O_RDONLY | os.O_NOFOLLOW | getattr(os, "O_NONBLOCK", 0))
        except OSError:
            continue
        with os.fdopen(fd, "rb") as f:
            info = os.fstat(f.fileno())
            if not stat.S_ISREG(info.st_mode) or info.st_size > MAX_IMAGE_BYTES:
                why = f"the image {sanitise_text(path)[:200]!r} is not a PNG file of sane size"
                continue
            data = f.read(MAX_IMAGE_BYTES + 1)
        if len(data) > MAX_IMAGE_BYTES or not data.startswith(PNG_MAGIC):
            why = f"the image {sanitise_text(path)[:200]!r} is not a PNG file of sane size"
            continue
        return data, ""
    return None, why


def _text(value: object, limit: int | None = None) -> str:
    """Text a draft or a report produced, sanitised, clipped to `limit` characters, then
    HTML-escaped (quotes included: safe in an attribute too)."""
    text = sanitise_text(value)
    if limit is not None and len(text) > limit:
        text = text[: limit - 1] + "…"
    return html.escape(text)


def _img(data: bytes, name: str) -> str:
    encoded = base64.b64encode(data).decode()
    return f'<img src="data:image/png;base64,{encoded}" alt="{_text(name)}">'


def _when(t: float | None) -> str:
    import time

    return "–" if t is None else time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(t))


def _minutes(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.1f} min"


def _attempt_usage(events: list[dict], function: str, attempt: int) -> tuple[str, str]:
    """(time from the call to its check, tokens and cost) of one attempt, for its heading."""

    def at(kind: str) -> float | None:
        return next((e["t"] for e in events if e["event"] == kind
                     and (e.get("function"), e.get("attempt")) == (function, attempt)), None)  # fmt: skip

    start, end = at("call"), at("checked")
    took = _minutes(end - start) if start is not None and end is not None else "–"
    response = next((e for e in events if e["event"] == "response"
                     and (e.get("function"), e.get("attempt")) == (function, attempt)), None)  # fmt: skip
    if response is None:
        return took, "no call (a saved answer)"
    u = response.get("usage", {})
    return took, (
        f"{u.get('input_tokens', 0)} in, {u.get('output_tokens', 0)} out, "
        f"{u.get('cache_read_tokens', 0)} cache-read tokens; ${u.get('usd', 0.0):.2f}"
    )


def _header(journal: Journal, events: list[dict], usage: dict, set_hash: str | None) -> str:
    """Who, what, when and how much, first: what a reviewer asks before reading on."""
    started = next((e for e in events if e["event"] == "started"), {})
    config = started.get("config", {})
    author = config.get("author") or {}
    who = (
        f"{author.get('provider', '?')} · {author.get('model', '?')}"
        if author.get("kind") == "model"
        else "people: " + ", ".join(author.get("names", []))
        if author.get("kind") == "people"
        else "unknown (the journal predates this field)"
    )
    if author.get("note"):
        who += f" ({author['note']})"
    first, last = (events[0]["t"], events[-1]["t"]) if events else (None, None)
    ended = next((e["event"] for e in reversed(events) if e["event"] in ("finished", "exhausted",
                  "call_failed", "refused")), "did not finish")  # fmt: skip
    rows = [
        ("domain", config.get("domain", "–")),
        ("author", who),
        ("commit", config.get("commit") or "–"),
        ("set hash", set_hash or "– (nothing frozen from this run)"),
        ("date", _when(first)),
        ("total time", _minutes(last - first) if first is not None else "–"),
        ("ended", ended),
        (
            "tokens",
            f"{usage['input']} input, {usage['output']} output, {usage['cache_write']} "
            f"cache-write, {usage['cache_read']} cache-read",
        ),
        ("cost", f"${usage['usd']:.2f}"),
        ("case seed", str(config.get("cases_seed", "–"))),
    ]
    return (
        "<table class=head>"
        + "".join(f"<tr><th>{k}</th><td>{_text(v)}</td></tr>" for k, v in rows)
        + "</table>"
    )


def write_report(journal: Journal, title: str, *, set_hash: str | None = None) -> Path:
    """Write `report.html` in the run's folder. `set_hash`: the frozen set this run produced."""
    events = journal.events()
    usage = {"input": 0, "output": 0, "cache_write": 0, "cache_read": 0, "usd": 0.0}
    for e in events:
        if e["event"] == "response":
            u = e.get("usage", {})
            usage["input"] += u.get("input_tokens", 0)
            usage["output"] += u.get("output_tokens", 0)
            usage["cache_write"] += u.get("cache_write_tokens", 0)
            usage["cache_read"] += u.get("cache_read_tokens", 0)
            usage["usd"] += u.get("usd", 0.0)
    frozen = {e["function"]: e["attempt"] for e in events if e["event"] == "frozen"}
    out = [
        f"<!doctype html><meta charset=utf-8><title>{html.escape(title)}</title><style>{_CSS}</style>"
    ]
    out.append(f"<h1>{html.escape(title)}</h1>")
    out.append(_header(journal, events, usage, set_hash))
    out.append(
        "<table><tr><th>function</th><th>attempts</th><th>result</th></tr>"
        + "".join(
            f"<tr><td>{f}</td><td>{_attempts(journal, f)}</td><td class={'passed' if f in frozen else 'failed'}>"
            f"{'frozen at attempt ' + str(frozen[f]) if f in frozen else 'not frozen'}</td></tr>"
            for f in authoring_order()
        )
        + "</table>"
    )
    for function in authoring_order():
        n = _attempts(journal, function)
        if not n:
            continue
        out.append(f"<h2>{function}</h2>")
        previous = None
        for k in range(1, n + 1):
            report = journal.saved_report(function, k)
            draft_path = journal.dir / "drafts" / f"{function}-{k}.py"
            draft = draft_path.read_text() if draft_path.is_file() else None
            status = "passed" if report and report["passed"] else "failed"
            took, spent = _attempt_usage(events, function, k)
            prompt = journal.dir / "requests" / f"{function}-{k}.md"
            link = (
                f' · <a href="requests/{function}-{k}.md">the prompt</a>'
                if prompt.is_file()
                else ""
            )
            out.append(
                f"<h3>attempt {k}: <span class={status}>{status}</span></h3>"
                f"<p class=meta>{_text(took)} · {_text(spent)}{link}</p>"
            )
            if report:
                out.append(
                    "<table><tr><th>check</th><th>category</th><th>status</th><th>message</th></tr>"
                )
                for c in report["checks"]:
                    status = _text(c.get("status", ""))
                    message = str(c.get("message", ""))
                    shown = (  # the whole message: a long one folded, never cut
                        f"<details><summary>{_text(message, 300)}</summary>"
                        f"<pre>{_text(message)}</pre></details>"
                        if len(message) > 300
                        else _text(message)
                    )
                    out.append(
                        f"<tr><td>{_text(c.get('name', ''))}</td><td>{_text(c.get('category', ''))}</td>"
                        f'<td class="{status}">{status}</td><td>{shown}</td></tr>'
                    )
                out.append("</table>")
                for c in report["checks"]:
                    for image in c.get("images", []):
                        if not isinstance(image, dict):
                            continue
                        path = image.get("path")
                        data, why = report_image(path, journal.images_dir(function, k))
                        label = _text(f"{c.get('name')}: {image.get('caption', '')}")
                        if data is None:
                            out.append(
                                f"<p class=failed>{label}: image refused: {html.escape(why)}</p>"
                            )
                        else:
                            out.append(f"<p>{label}</p>{_img(data, Path(str(path)).name)}")
                md = journal.saved_markdown(function, k)
                if md and not report["passed"]:
                    out.append(
                        f"<details><summary>feedback sent to the model</summary><pre>{_text(md)}</pre></details>"
                    )
            if draft is not None:
                if previous is not None:
                    diff = difflib.HtmlDiff(wrapcolumn=90).make_table(  # escapes HTML itself
                        sanitise_text(previous).splitlines(),
                        sanitise_text(draft).splitlines(),
                        f"attempt {k - 1}",
                        f"attempt {k}",
                        context=True,
                    )
                    out.append(
                        f"<details open><summary>diff from attempt {k - 1}</summary>{diff}</details>"
                    )
                else:
                    out.append(
                        f"<details><summary>draft</summary><pre>{_text(draft)}</pre></details>"
                    )
                previous = draft
    path = journal.dir / "report.html"
    path.write_text("\n".join(out))
    return path


def _attempts(journal: Journal, function: str) -> int:
    return max(
        (
            e["attempt"]
            for e in journal.events()
            if e["event"] == "checked" and e["function"] == function
        ),
        default=0,
    )


def summary(journal: Journal) -> dict:
    """Per function: attempts and the check counts of its last report (for the manifest)."""
    out: dict[str, dict] = {}
    for function in FUNCTIONS:
        n = _attempts(journal, function)
        report = journal.saved_report(function, n) if n else None
        if report:
            counts = {
                s: sum(c["status"] == s for c in report["checks"])
                for s in ("passed", "failed", "skipped")
            }
            counts["failed"] += sum(c["status"] == "error" for c in report["checks"])
            out[function] = {
                "attempts": n,
                "checks": counts,
                "cases_seed": report.get("cases_seed"),
            }
    return out


def dumps(value: object) -> str:
    return json.dumps(value, indent=2, sort_keys=True)
