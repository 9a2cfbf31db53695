"""Reference entry points, and the shape a check suite's entry point takes.

An entry point is ``fn(ctx: EntryContext) -> output``; a job names it as
``entry="sandbox.harness.entries:call_many"``. `call_many` runs the draft's function on many
inputs in one job (one fork), reporting each call's result or exception, which is what a
property check needs.
"""

from __future__ import annotations

import time
from typing import Any

from .context import EntryContext


def call(ctx: EntryContext) -> Any:
    """The draft's function on the job's inputs (what ``entry="call"`` does)."""
    return ctx.fn(**ctx.inputs)


def call_many(ctx: EntryContext) -> list[dict[str, Any]]:
    """The draft's function on each of ``inputs["calls"]`` (a list of keyword-argument dicts).

    Returns one ``{"ok": output, "seconds": s}`` or ``{"error": {"type", "message"},
    "seconds": s}`` per call, in order; an exception in one call does not stop the others.
    """
    fn = ctx.fn
    results: list[dict[str, Any]] = []
    for kwargs in ctx.inputs.get("calls", []):
        t0 = time.perf_counter()
        try:
            results.append({"ok": fn(**kwargs)})
        except Exception as e:
            results.append({"error": {"type": type(e).__name__, "message": str(e)[:2000]}})
        results[-1]["seconds"] = time.perf_counter() - t0
    return results
