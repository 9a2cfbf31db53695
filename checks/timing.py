"""What the speed gate measures: each call's time on an input its session has not seen.

Design rule: the checks call a draft several times on the same input (determinism, shared
cases), and a draft keeps its process between calls, so it can remember an answer. Online,
every scene is new. So `interface.fast_enough` counts a call only when its input is new to
the session — the first call on it, keyed by a content hash of the arguments computed here, on
the host, from the values sent. Inputs a suite derives from one it sent before (the same
records reordered or moved, for the invariance properties) are not counted either: a draft
that remembers answers by a normalised scene would answer them from memory, so they would
only dilute the sample of new scenes.

Both the CPU time and the wall time PID 1 measured are judged (`sandbox.CallReport`): CPU time
because it is steady under load, wall time because a call that sleeps or blocks costs the
online pass all the same. The wall time judged is the call's wall time less its wait for a CPU
(`queued_seconds`: the largest run-queue delay any one of its threads gained, plus the
harness's while it relayed): about what the call takes on an idle machine, so that a busy
checking machine (a 2-core runner running tests, where a program waits for a CPU for most of
its wall time) does not fail a program that a quiet one passes.
"""

from __future__ import annotations

import hashlib
import statistics
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True, kw_only=True)
class CallTiming:
    """One returned call of the judged function: what it cost and whether its input was new.

    Attributes:
        label: the case the call was made for (shown in reports).
        cpu_s: CPU time of the call, measured outside the draft [s].
        wall_s: wall time from request to answer, measured outside the draft [s].
        queued_s: of `wall_s`, how long the call waited for a CPU [s].
        key: content hash of the call's arguments.
        first: the session had not been called on these arguments before, and the suite did
            not derive them from arguments it had sent (what the speed gate counts).
    """

    label: str
    cpu_s: float
    wall_s: float
    queued_s: float = 0.0
    key: str
    first: bool

    @property
    def ready_s(self) -> float:
        """Wall time less the wait for a CPU: about the call's wall time on an idle machine."""
        return max(0.0, self.wall_s - self.queued_s)


@dataclass(kw_only=True)
class TimingLog:
    """Every returned call of the judged function, each marked first or not on its input."""

    calls: list[CallTiming] = field(default_factory=list)
    seen: set[str] = field(default_factory=set)
    derived: set[str] = field(default_factory=set)

    def mark_derived(self, args: Iterable[Any]) -> None:
        """The coming call's arguments are derived from a case already sent (reordered,
        moved): its time is not counted."""
        self.derived.add(input_key(args))

    def record(self, label: str, args: Iterable[Any], result: Any) -> None:
        """Note a call of the judged function (`result`: a `checks.calls.CallResult`); one
        that did not return (timeout, crash) counts its input as seen but not its time."""
        key = input_key(args)
        first = key not in self.seen and key not in self.derived
        self.seen.add(key)
        if result.verdict in ("ok", "exception"):
            self.calls.append(
                CallTiming(
                    label=label,
                    cpu_s=float(result.cpu_seconds),
                    wall_s=float(result.seconds),
                    queued_s=float(getattr(result, "queued_seconds", 0.0)),
                    key=key,
                    first=first,
                )
            )

    def speed(self) -> Speed | None:
        """Medians and maxima over the first calls on each input; None when there are none."""
        return speed_of(self.calls)


@dataclass(frozen=True, kw_only=True)
class Speed:
    """Medians and maxima over the calls on inputs new to the session."""

    calls: int  # how many returned calls there were
    fresh: int  # how many of them were the first on their input
    cpu_median_s: float
    cpu_max_s: float
    cpu_max_label: str
    wall_median_s: float
    wall_max_s: float
    wall_max_label: str
    ready_median_s: float  # wall time less the wait for a CPU: what the gate judges
    ready_max_s: float
    ready_max_label: str


def input_key(args: Iterable[Any]) -> str:
    """A content hash of call arguments: equal for equal values (dict key order aside)."""
    h = hashlib.sha256()
    for a in args:
        _feed(h, a)
    return h.hexdigest()


def _feed(h: Any, v: Any) -> None:
    if isinstance(v, np.ndarray):
        a = np.ascontiguousarray(v)
        h.update(f"a{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    elif isinstance(v, Mapping):
        items = sorted(v.items(), key=lambda kv: repr(kv[0]))
        h.update(f"d{len(items)}".encode())
        for k, x in items:
            _feed(h, k)
            _feed(h, x)
    elif isinstance(v, (list, tuple)):
        h.update(f"l{len(v)}".encode())
        for x in v:
            _feed(h, x)
    elif isinstance(v, np.generic):
        _feed(h, v.item())
    else:  # str, numbers, None, bool, `sandbox.Const`
        text = repr(v).encode()
        h.update(f"{type(v).__name__}:{len(text)}:".encode())
        h.update(text)


def new_input_calls(timings: Iterable[CallTiming]) -> list[CallTiming]:
    """The calls whose input the session had not seen before."""
    return [t for t in timings if t.first]


def speed_of(timings: list[CallTiming]) -> Speed | None:
    """Medians and maxima over the first calls on each input; None when there are none."""
    fresh = new_input_calls(timings)
    if not fresh:
        return None
    cpu = max(fresh, key=lambda t: t.cpu_s)
    wall = max(fresh, key=lambda t: t.wall_s)
    ready = max(fresh, key=lambda t: t.ready_s)
    return Speed(
        calls=len(timings),
        fresh=len(fresh),
        cpu_median_s=statistics.median(t.cpu_s for t in fresh),
        cpu_max_s=cpu.cpu_s,
        cpu_max_label=cpu.label,
        wall_median_s=statistics.median(t.wall_s for t in fresh),
        wall_max_s=wall.wall_s,
        wall_max_label=wall.label,
        ready_median_s=statistics.median(t.ready_s for t in fresh),
        ready_max_s=ready.ready_s,
        ready_max_label=ready.label,
    )


__all__ = ["CallTiming", "Speed", "TimingLog", "input_key", "new_input_calls", "speed_of"]
