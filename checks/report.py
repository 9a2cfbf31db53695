"""Check results and the check report: the model's feedback, as data and as Markdown.

Design rule: a report is a plain dict valid against `check_report.schema.json`; checks appear
in a fixed order (interface, schema, property, domain, image; within a category, the order the
suite declares), `first_failure` is the first check that did not pass, and "passed" means every
required check ran and passed: a skipped check counts as a failure unless it was declared
optional (with the reason the report shows), and a check that found nothing to examine is not a
pass. Nothing depends on the machine or the moment except the timings (`duration_s`, and the
metrics ending in ``_s``), so the same draft checked twice gives the same report once those are
left out (`comparable`). Every string a draft could have put into a report (its exception
messages, its ids) is made safe for a terminal, a file, HTML and a model. `report_markdown`
renders the short, specific text that goes into the model's prompt.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import PurePath
from typing import Any, Literal

import numpy as np

from contracts.validate import to_jsonable, validate
from sandbox.harness.wire import clean_text

Category = Literal["interface", "schema", "property", "domain", "image"]
Status = Literal["passed", "failed", "error", "skipped"]
CATEGORIES: tuple[str, ...] = ("interface", "schema", "property", "domain", "image")
MAX_TRACEBACK = 2500  # [chars] kept of a traceback (its end)
MAX_TEXT = 1500  # [chars] of a message
MAX_JSON = 6000  # [chars] of a JSON value shown (expected, actual, counterexample)
MAX_OBJECTS = 32  # per-object rows kept in a check


@dataclass(kw_only=True)
class CheckResult:
    """One check's outcome (see `check_report.schema.json` for the fields)."""

    name: str
    category: Category
    status: Status = "passed"
    message: str = ""
    expected: Any = None
    actual: Any = None
    counterexample: Any = None
    seed: int | None = None
    examples: int | None = None
    traceback: str = ""
    metrics: dict[str, float | None] = field(default_factory=dict)
    images: list[dict[str, str]] = field(default_factory=list)
    duration_s: float | None = None
    optional: str = ""  # why a skip of this check is no failure ("" : it is required)
    rule: str = ""  # what the check enforces, as the prompt states it (`checks.rules`)
    failures: int | None = None  # how many of the `examples` failed (None: not counted)
    limits: dict[str, float] = field(default_factory=dict)  # tolerances and budgets used
    objects: list[dict[str, Any]] = field(default_factory=list)  # per object, on the case shown

    @property
    def failing(self) -> bool:
        return self.status in ("failed", "error")

    @property
    def passes(self) -> bool:
        """Passed, or skipped where the check is optional."""
        return self.status == "passed" or (self.status == "skipped" and bool(self.optional))

    def fail(self, message: str, **fields: Any) -> CheckResult:
        self.status = "failed"
        self.message = message
        for k, v in fields.items():
            setattr(self, k, v)
        return self

    def to_dict(self) -> dict[str, Any]:
        status = self.status
        message = self.message
        if status == "passed" and self.examples == 0:  # nothing was examined: not a pass
            status = "skipped"
            message = message or "nothing to check: no case reached this check"
        d: dict[str, Any] = {"name": self.name, "category": self.category, "status": status}
        if self.optional:
            d["optional"] = clean_text(self.optional)
        if message:
            d["message"] = clean_text(_clip(message, MAX_TEXT))
        for key in ("expected", "actual", "counterexample"):
            value = getattr(self, key)
            if value is not None:
                d[key] = jsonable(value)
        if self.seed is not None:
            d["seed"] = int(self.seed)
        if self.examples is not None:
            d["examples"] = int(self.examples)
        if self.failures is not None and status in ("failed", "error"):
            d["failures"] = int(self.failures)
        if self.rule:
            d["rule"] = clean_text(self.rule)
        if self.limits:
            d["limits"] = {k: _metric(v) for k, v in sorted(self.limits.items())}
        if self.objects:
            d["objects"] = [jsonable(o) for o in self.objects[:MAX_OBJECTS]]
        if self.traceback:
            d["traceback"] = clean_text(trim_traceback(self.traceback))
        if self.metrics:
            d["metrics"] = {k: _metric(v) for k, v in sorted(self.metrics.items())}
        if self.images:
            d["images"] = [dict(i) for i in self.images]
        if self.duration_s is not None:
            d["duration_s"] = round(max(0.0, float(self.duration_s)), 3)
        return d

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> CheckResult:
        return CheckResult(**{k: v for k, v in d.items()})


def passes(check: Mapping[str, Any]) -> bool:
    """A check dict passed, or was skipped and is optional."""
    return check["status"] == "passed" or (check["status"] == "skipped" and "optional" in check)


def _metric(v: Any) -> float | None:
    if v is None:
        return None
    f = float(v)
    return None if not math.isfinite(f) else round(f, 6)


def _clip(text: str, n: int) -> str:
    return text if len(text) <= n else text[: n - 1] + "…"


def trim_traceback(tb: str, limit: int = MAX_TRACEBACK) -> str:
    """The end of a traceback (where the error is), at most `limit` characters."""
    tb = tb.strip()
    if len(tb) <= limit:
        return tb
    return "…\n" + tb[-(limit - 2) :]


def jsonable(value: Any, digits: int = 6) -> Any:
    """A JSON value: arrays as lists, floats rounded to `digits` decimals, non-finite as None."""
    value = to_jsonable(value)
    if isinstance(value, float):
        return round(value, digits) + 0.0 if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): jsonable(v, digits) for k, v in value.items()}
    if isinstance(value, list):
        return [jsonable(v, digits) for v in value]
    if isinstance(value, str):
        return clean_text(value)
    if isinstance(value, bool | int) or value is None:
        return value
    return clean_text(repr(value)[:MAX_TEXT])


def order_checks(checks: Iterable[CheckResult | Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Check dicts sorted by category (stable within a category)."""
    dicts = [c.to_dict() if isinstance(c, CheckResult) else dict(c) for c in checks]
    return sorted(dicts, key=lambda c: CATEGORIES.index(c["category"]))


def build_report(
    *,
    domain: str,
    function: str,
    source: str,
    checks: Sequence[CheckResult | Mapping[str, Any]],
    duration_s: float | None = None,
    rules: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The check report dict (validated against its schema).

    Args:
        rules: check name → its stated rule (`checks.rules.Stated`): each check of that name
            gets the rule's text as ``rule`` and the values it states as ``limits`` (the
            tolerances and budgets it judged by), unless it has its own.
    """
    ordered = order_checks(checks)
    for c in ordered:
        stated = (rules or {}).get(c["name"])
        if stated is None:
            continue
        c.setdefault("rule", clean_text(stated.text))
        limits = stated.limits()
        if limits and "limits" not in c:
            c["limits"] = {k: _metric(v) for k, v in sorted(limits.items())}
    failing = [c["name"] for c in ordered if not passes(c)]
    report: dict[str, Any] = {
        "schema_version": 1,
        "domain": domain,
        "function": function,
        "passed": not failing,
        "draft_sha256": hashlib.sha256(source.encode()).hexdigest(),
        "first_failure": failing[0] if failing else None,
        "checks": ordered,
    }
    if duration_s is not None:
        report["duration_s"] = round(max(0.0, duration_s), 3)
    validate("check_report", report)
    return report


def comparable(report: Mapping[str, Any]) -> dict[str, Any]:
    """The report without its timings: equal for equal drafts checked on equal inputs."""

    def check(c: Mapping[str, Any]) -> dict[str, Any]:
        out = {k: v for k, v in c.items() if k != "duration_s"}
        if "metrics" in out:
            out["metrics"] = {k: v for k, v in out["metrics"].items() if not k.endswith("_s")}
        return out

    out = {k: v for k, v in report.items() if k != "duration_s"}
    out["checks"] = [check(c) for c in report["checks"]]
    return out


# -- Markdown for the prompt --------------------------------------------------------------------


def compact_poses(value: Any) -> Any:
    """Poses (4×4) shown as position [m] and yaw [deg] when upright, else position and rotation
    rows: how scene specs read in the prompt."""
    if isinstance(value, dict):
        return {
            k: _pose_text(v) if k in ("pose", "target_pose") else compact_poses(v)
            for k, v in value.items()
        }
    if isinstance(value, list):
        return [compact_poses(v) for v in value]
    return value


def _pose_text(T: Any) -> Any:
    try:
        M = np.asarray(T, dtype=float)
    except (TypeError, ValueError):
        return T
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        return T
    xyz = [round(float(v), 4) for v in M[:3, 3]]
    if abs(M[2, 2] - 1) < 1e-6 and np.allclose(M[3], [0, 0, 0, 1]):
        yaw = float(np.degrees(np.arctan2(M[1, 0], M[0, 0])))
        return {"xyz_m": xyz, "yaw_deg": round(yaw, 1)}
    return {
        "xyz_m": xyz,
        "R": [[round(float(v), 3) for v in row] for row in M[:3, :3]],
        "last_row": [round(float(v), 3) for v in M[3]],
    }


def _short_json(value: Any, limit: int = 1200) -> str:
    text = json.dumps(compact_poses(value), separators=(", ", ": "))
    return _clip(text, limit)


def report_markdown(report: Mapping[str, Any], *, max_failures: int = 3) -> str:
    """Short, specific Markdown of a report for the model: what failed first, why, on what.

    The first failing check is shown in full (message, expected vs actual, the shrunk
    counterexample, the traceback, images); up to `max_failures - 1` further failures get one
    line each; passing checks are only counted.
    """
    fn, checks = report["function"], report["checks"]
    passed = sum(c["status"] == "passed" for c in checks)
    failing = [c for c in checks if not passes(c)]
    skipped = sum(c["status"] == "skipped" for c in checks)
    if not failing:
        return f"**`{fn}` passed all {passed} checks** ({report['domain']})."
    lines = [
        f"**`{fn}` failed {len(failing)} of {len(checks)} checks** "
        f"({passed} passed{f', {skipped} skipped' if skipped else ''})."
    ]
    first = failing[0]
    lines += ["", f"### First failure: `{first['name']}` ({first['category']})"]
    if first.get("rule"):
        lines += ["", f"Rule: {first['rule']}"]
    if first.get("message"):
        lines += ["", first["message"]]
    if "failures" in first and "examples" in first:
        lines += ["", f"- failed on {first['failures']} of {first['examples']} cases checked"]
    if "expected" in first:
        lines += ["", f"- expected: `{_short_json(first['expected'], 600)}`"]
    if "actual" in first:
        lines += [f"- actual: `{_short_json(first['actual'], 600)}`"]
    if first.get("metrics"):
        shown = ", ".join(
            f"{k} = {'n/a' if v is None else f'{v:.4g}'}" for k, v in first["metrics"].items()
        )
        lines += [f"- metrics: {shown}"]
    if first.get("objects"):
        lines += ["", *_table(first["objects"])]
    if "counterexample" in first:
        lines += [
            "",
            "Smallest failing input found (poses as position and yaw about z)"
            + (f" (seed {first['seed']})" if "seed" in first else "")
            + ":",
            "```json",
            _short_json(first["counterexample"], 2500),
            "```",
        ]
    if first.get("traceback"):
        lines += ["", "Traceback (end):", "```", trim_traceback(first["traceback"], 1500), "```"]
    for img in first.get("images", []):
        lines += [
            "",
            # the file's name alone: the run's folder is not the model's business and would
            # make the prompt differ from run to run (replays match prompts by their hash)
            f"Image: `{PurePath(str(img['path'])).name}`"
            + (f": {img['caption']}" if img.get("caption") else ""),
        ]
    rest = failing[1:max_failures]
    if rest:
        lines += ["", "Also failing:"]
        for c in rest:
            msg = _clip(c.get("message", "").splitlines()[0] if c.get("message") else "", 300)
            count = (
                f" [{c['failures']} of {c['examples']} cases]"
                if "failures" in c and "examples" in c
                else ""
            )
            lines += [f"- `{c['name']}` ({c['category']}){count}: {msg}"]
        if len(failing) > max_failures:
            lines += [f"- … and {len(failing) - max_failures} more"]
    return "\n".join(lines)


def _cell(v: Any) -> str:
    if isinstance(v, bool):
        return "yes" if v else "**no**"
    if isinstance(v, float):
        return f"{v:.3g}"
    return "–" if v is None else str(v).replace("|", "/")


def _table(rows: Sequence[Mapping[str, Any]], limit: int = 12) -> list[str]:
    """Per-object rows as a Markdown table (the columns of the first row)."""
    cols = list(rows[0])
    out = ["| " + " | ".join(c.replace("_", " ") for c in cols) + " |"]
    out.append("|" + "---|" * len(cols))
    for row in rows[:limit]:
        out.append("| " + " | ".join(_cell(row.get(c)) for c in cols) + " |")
    if len(rows) > limit:
        out.append(f"(… {len(rows) - limit} more objects)")
    return out


def images_of(report: Mapping[str, Any]) -> list[str]:
    """Paths of every image a report refers to, failing checks first."""
    checks = sorted(report["checks"], key=passes)
    return [i["path"] for c in checks for i in c.get("images", [])]


def array_digest(a: np.ndarray) -> str:
    """A short content hash of an array (shape, dtype and bytes)."""
    a = np.ascontiguousarray(a)
    h = hashlib.sha256(f"{a.shape}{a.dtype}".encode())
    h.update(a.tobytes())
    return h.hexdigest()[:16]
