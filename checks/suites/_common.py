"""Helpers shared by the function suites: scene transforms, canonical forms, check wrappers."""

from __future__ import annotations

import time
import traceback
from collections import Counter
from collections.abc import Callable, Collection, Iterator, Mapping, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any

import numpy as np

from checks.hypo import Failure
from checks.report import CheckResult, jsonable


def pose(value: Any) -> np.ndarray:
    return np.array(value, dtype=float)


def copy_records(records: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    return [{"id": r["id"], "mesh": r["mesh"], "pose": pose(r["pose"])} for r in records]


def translated(records: Sequence[Mapping[str, Any]], dx: float, dy: float) -> list[dict]:
    """Records moved by (dx, dy, 0) [m]."""
    out = copy_records(records)
    for r in out:
        r["pose"][0, 3] += dx
        r["pose"][1, 3] += dy
    return out


def permuted(records: Sequence[Mapping[str, Any]], order: Sequence[int]) -> list[dict]:
    return [copy_records(records)[i] for i in order]


def order_keys(n: int) -> Any:
    """A strategy for record orders of up to `n` records: sort keys, shrinking to no change."""
    from hypothesis import strategies as st

    return st.tuples(*[st.integers(0, 9) for _ in range(max(n, 1))])


def order_from_keys(keys: Sequence[int], n: int) -> list[int]:
    """The record order that sorting the first `n` keys gives (stable: zeros keep the order)."""
    return [int(i) for i in np.argsort(np.asarray(keys[:n]), kind="stable")]


def scene_spec(domain: str, records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The scene spec (JSON, poses rounded to 0.1 µm) of records: how counterexamples read."""
    return {
        "domain": domain,
        "objects": [
            {"id": r["id"], "mesh": r["mesh"], "pose": jsonable(pose(r["pose"]), 7)}
            for r in records
        ],
    }


def edge_multiset(graph: Any) -> Counter:
    """(source, target, type) of every edge, as a multiset."""
    return Counter(
        (str(e.get("source")), str(e.get("target")), str(e.get("type")))
        for e in graph.get("edges", [])
    )


def same_value(a: Any, b: Any, atol: float = 1e-9) -> bool:
    """Equality of JSON-like values holding numpy arrays (numbers within `atol`)."""
    if isinstance(a, np.ndarray | np.generic) or isinstance(b, np.ndarray | np.generic):
        try:
            aa, bb = np.asarray(a), np.asarray(b)
            if aa.shape != bb.shape:
                return False
            if aa.dtype.kind in "biuf" and bb.dtype.kind in "biuf":
                return bool(np.allclose(aa, bb, atol=atol, rtol=0, equal_nan=True))
            return bool(np.array_equal(aa, bb))
        except (TypeError, ValueError):
            return False
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        return a.keys() == b.keys() and all(same_value(a[k], b[k], atol) for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(same_value(x, y, atol) for x, y in zip(a, b, strict=True))
    if isinstance(a, float | int) and isinstance(b, float | int) and not isinstance(a, bool):
        return abs(a - b) <= atol
    return a == b


def first_difference(a: Any, b: Any, path: str = "", atol: float = 1e-9) -> str:
    """Path of the first place where two values differ ('' when they are the same)."""
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        for k in list(a) + [k for k in b if k not in a]:
            if k not in a or k not in b:
                return f"{path}.{k}".lstrip(".")
            d = first_difference(a[k], b[k], f"{path}.{k}", atol)
            if d:
                return d.lstrip(".")
        return ""
    if isinstance(a, list | tuple) and isinstance(b, list | tuple) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            d = first_difference(x, y, f"{path}[{i}]", atol)
            if d:
                return d
        return ""
    return "" if same_value(a, b, atol) else (path.lstrip(".") or "(root)")


_ONLY: ContextVar[frozenset[str] | None] = ContextVar("rivet_checks_only", default=None)
ALWAYS_RUN = ("interface.", "schema.")  # what every other check rests on


@contextmanager
def selecting(names: Collection[str] | None) -> Iterator[None]:
    """Within it, only the checks `names` run (with the interface and schema checks, which
    the others rest on); the others are reported skipped. None: every check runs."""
    token = _ONLY.set(None if names is None else frozenset(names))
    try:
        yield
    finally:
        _ONLY.reset(token)


def selected(name: str) -> bool:
    names = _ONLY.get()
    return names is None or name.startswith(ALWAYS_RUN) or name in names


NOT_ASKED = "not asked for (--only)"  # why a check `selecting` leaves out is no failure


def unselected(name: str, category: str) -> CheckResult:
    """The report's entry for a check left out by `selecting`: skipped, and no failure."""
    return CheckResult(
        name=name,
        category=category,  # type: ignore[arg-type]
        status="skipped",
        message="not run: other checks were asked for (--only)",
        optional=NOT_ASKED,
    )


def if_selected(name: str, category: str, check: Callable[[], CheckResult]) -> CheckResult:
    """`check()` when `selecting` keeps `name`, else its skipped entry (for checks that build
    their result themselves rather than through `run_check`)."""
    return check() if selected(name) else unselected(name, category)


def run_check(
    name: str, category: str, body: Callable[[CheckResult], None], **fields: Any
) -> CheckResult:
    """Run `body(result)`, which fills `result` in; a `Failure` it raises fails the check.
    A check `selecting` leaves out is not run."""
    if not selected(name):
        return unselected(name, category)
    r = CheckResult(name=name, category=category, **fields)  # type: ignore[arg-type]
    t0 = time.perf_counter()
    try:
        body(r)
    except Failure as f:
        apply_failure(r, f)
    except Exception as e:  # the output is too malformed for this check to read
        r.status = "error"
        r.message = (
            f"this check could not evaluate the function's output ({type(e).__name__}: {e}); "
            "fix the failing schema check first"
        )
        r.traceback = traceback.format_exc()
    r.duration_s = time.perf_counter() - t0
    return r


def apply_failure(r: CheckResult, f: Failure) -> None:
    r.status = "error" if f.error else "failed"
    r.message = f.message
    r.expected = f.expected if f.expected is not None else r.expected
    r.actual = f.actual
    r.counterexample = f.counterexample
    r.traceback = f.traceback


def raise_first(r: CheckResult, found: Sequence[Failure], what: str) -> None:
    """Raise the first of the failures a check found over its cases, counted: the report says
    on how many of its `examples` it failed."""
    if not found:
        return
    r.failures = len(found)
    first = found[0]
    if r.examples and len(found) > 0:
        first.message += f" (fails on {len(found)} of {r.examples} {what})"
    raise first


def raised(what: str, result: Any, counterexample: Any = None, expected: Any = None) -> Failure:
    """The Failure for a draft call that raised or timed out."""
    return Failure(
        message=f"{what} {result.describe()}",
        expected=expected,
        actual=result.describe(),
        counterexample=counterexample,
        traceback=result.traceback,
        error=True,
    )
