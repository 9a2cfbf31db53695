"""Artifact review: the Markdown a pull request shows when a domain's frozen programs change."""

from __future__ import annotations

import difflib
import json
import subprocess
from pathlib import Path
from typing import Any

from artifacts.errors import ArtifactError
from artifacts.hashing import REPO
from contracts.errors import UsageError
from contracts.functions import FUNCTIONS

METRICS = ("state_ac", "plan_sr", "final_sr")


def _git_show(repo: Path, rev: str, path: str) -> str | None:
    proc = subprocess.run(
        ["git", "show", f"{rev}:{path}"], cwd=repo, capture_output=True, text=True
    )
    return proc.stdout if proc.returncode == 0 else None


def _rev_exists(repo: Path, rev: str) -> bool:
    proc = subprocess.run(
        ["git", "rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}"],
        cwd=repo,
        capture_output=True,
    )
    return proc.returncode == 0


def _read(path: Path) -> str | None:
    return path.read_text() if path.is_file() else None


def _json(text: str | None) -> dict[str, Any]:
    if not text:
        return {}
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return {}


EVAL_COMMAND = "rivet eval {domain} --policy artifacts"
"""What writes `artifacts/<domain>/eval.json`: the whole dev benchmark, front camera, honest
protocol, on the frozen set (see rivet/commands/eval.py), run from the repository root."""


def _unmeasured(manifest: dict[str, Any], evaluation: dict[str, Any]) -> str | None:
    """Why `evaluation` does not measure `manifest`'s set (None: it does)."""
    if not evaluation:
        return "no `eval.json`"
    measured = evaluation.get("set_hash")
    if not isinstance(measured, str):
        return "`eval.json` names no set hash"
    if measured != manifest.get("set_hash"):
        return f"`eval.json` measured set `{measured[:16]}`, not this one"
    return None


def _metrics(
    domain: str, rev: str, before: tuple[dict, dict], after: tuple[dict, dict]
) -> list[str]:
    """The metrics table: each side's figures only when its eval.json measured its set."""
    command = EVAL_COMMAND.format(domain=domain)
    cells: list[dict[str, str]] = []
    notes: list[str] = []
    for label, where, (manifest, evaluation) in (
        ("Before", f"at `{rev}`", before),
        ("After", "in the working tree", after),
    ):
        if not manifest:  # no set on this side: nothing to measure
            cells.append({k: "–" for k in (*METRICS, "trials")})
            continue
        why = _unmeasured(manifest, evaluation)
        if why is None:
            pct = lambda v: "–" if v is None else f"{100 * v:.1f}%"  # noqa: E731
            cells.append(
                {k: pct(evaluation.get(k)) for k in METRICS}
                | {"trials": str(evaluation.get("trials", "–"))}
            )
            continue
        cells.append({k: "not evaluated" for k in (*METRICS, "trials")})
        run = (
            f"run `{command}` (it writes `artifacts/{domain}/eval.json`)"
            if label == "After"
            else f"on a checkout of `{rev}`, run `{command}`"
        )
        notes.append(
            f"{label} (set `{str(manifest.get('set_hash'))[:16]}` {where}): **not evaluated** — "
            f"{why}. To measure it, {run}."
        )
    out = ["", "| metric | before | after |", "|---|---|---|"]
    for k in (*METRICS, "trials"):
        out.append(f"| {k} | {cells[0][k]} | {cells[1][k]} |")
    if notes:
        out += [""] + [f"- {n}" for n in notes]
    return out


def diff_markdown(domain: str, rev: str = "HEAD", repo: Path = REPO) -> str:
    """Markdown comparing `<repo>/artifacts/<domain>/` at git `rev` with the working tree."""
    if not _rev_exists(repo, rev):
        raise UsageError(f"unknown git revision '{rev}'")
    root = repo / "artifacts"
    rel = f"artifacts/{domain}"
    old_m = _json(_git_show(repo, rev, f"{rel}/manifest.json"))
    new_m = _json(_read(root / domain / "manifest.json"))
    if not old_m and not new_m:
        raise ArtifactError(f"no artifacts for '{domain}' at {rev} or in the working tree")
    out = [f"## RIVET artifacts: `{domain}` ({rev} → working tree)", ""]
    old_set, new_set = old_m.get("set_hash"), new_m.get("set_hash")
    if old_set == new_set:
        out.append(f"Set hash unchanged: `{(new_set or '')[:16]}`.")
    else:
        out.append(
            f"**Set hash changed**: `{(old_set or 'none')[:16]}` → `{(new_set or 'none')[:16]}`."
        )
    if old_m.get("author") != new_m.get("author"):
        out.append(
            f"Author: `{json.dumps(old_m.get('author'))}` → `{json.dumps(new_m.get('author'))}`."
        )
    out += [
        "",
        "| function | changed | checks passed (before → after) | attempts |",
        "|---|---|---|---|",
    ]
    changed = []
    for f in FUNCTIONS:
        o = old_m.get("functions", {}).get(f, {})
        n = new_m.get("functions", {}).get(f, {})
        is_changed = o.get("sha256") != n.get("sha256")
        if is_changed:
            changed.append(f)
        oc, nc = o.get("checks", {}), n.get("checks", {})
        out.append(
            f"| `{f}` | {'**yes**' if is_changed else 'no'} | "
            f"{oc.get('passed', '–')}/{oc.get('passed', 0) + oc.get('failed', 0) or '–'} → "
            f"{nc.get('passed', '–')}/{nc.get('passed', 0) + nc.get('failed', 0) or '–'} | "
            f"{o.get('attempts', '–')} → {n.get('attempts', '–')} |"
        )
    old_e = _json(_git_show(repo, rev, f"{rel}/eval.json"))
    new_e = _json(_read(root / domain / "eval.json"))
    out += _metrics(domain, rev, (old_m, old_e), (new_m, new_e))
    for f in changed:
        before = (_git_show(repo, rev, f"{rel}/{f}.py") or "").splitlines(keepends=True)
        after = (_read(root / domain / f"{f}.py") or "").splitlines(keepends=True)
        diff = "".join(difflib.unified_diff(before, after, f"a/{rel}/{f}.py", f"b/{rel}/{f}.py"))
        out += [
            "",
            f"<details><summary><code>{f}.py</code></summary>",
            "",
            "```diff",
            diff.rstrip(),
            "```",
            "",
            "</details>",
        ]
    return "\n".join(out) + "\n"
