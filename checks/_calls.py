"""Calling a draft from a check: fresh copies of the inputs, a time budget, a short traceback.

A draft runs in the same process as the suite (inside the sandbox's forked child). Each call
gets deep copies of its arguments, so a draft that mutates its inputs cannot change what the
next call sees, and an interval timer that raises `CallTimeout` (a BaseException, so a draft's
``except Exception`` does not swallow it) when the call overruns its budget. The timer needs
the main thread; elsewhere calls run without one (the job's own time limit still holds).
"""

from __future__ import annotations

import copy
import signal
import threading
import time
import traceback
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any


class CallTimeout(BaseException):
    """A draft call ran past its time budget."""


@dataclass(frozen=True, kw_only=True)
class CallResult:
    """What one call of the draft did."""

    value: Any = None
    error: BaseException | None = None
    traceback: str = ""
    seconds: float = 0.0
    timed_out: bool = False

    @property
    def ok(self) -> bool:
        return self.error is None and not self.timed_out

    def describe(self) -> str:
        """One line: the exception type and message, or the timeout."""
        if self.timed_out:
            return f"did not return within its {self.seconds:.1f} s budget"
        if self.error is not None:
            return f"raised {type(self.error).__name__}: {_message(self.error)}"
        return "returned"


def _message(e: BaseException) -> str:
    try:
        return str(e)[:500]
    except Exception:
        return "<unprintable>"


def _on_alarm(signum: int, frame: Any) -> None:
    raise CallTimeout()


def call(fn: Callable, *args: Any, timeout: float, files: Iterable[str] = ()) -> CallResult:
    """Call `fn(*deep copies of args)` within `timeout` [s].

    Args:
        files: file names of the draft's modules (``plan.py``): the traceback keeps their
            frames and the frame that raised.
    """
    args = copy.deepcopy(args)
    timer = threading.current_thread() is threading.main_thread() and timeout > 0
    previous = None
    if timer:
        previous = signal.signal(signal.SIGALRM, _on_alarm)
        signal.setitimer(signal.ITIMER_REAL, timeout)
    t0 = time.perf_counter()
    try:
        value = fn(*args)
        seconds = time.perf_counter() - t0
        if timer:
            signal.setitimer(signal.ITIMER_REAL, 0)
        return CallResult(value=value, seconds=seconds)
    except CallTimeout:
        return CallResult(timed_out=True, seconds=timeout)
    except Exception as e:  # the draft's failure is data
        seconds = time.perf_counter() - t0
        if timer:
            signal.setitimer(signal.ITIMER_REAL, 0)
        return CallResult(error=e, traceback=format_traceback(e, files), seconds=seconds)
    finally:
        if timer:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous or signal.SIG_DFL)


def format_traceback(e: BaseException, files: Iterable[str] = ()) -> str:
    """The draft's frames of an exception's traceback, plus the frame that raised it."""
    names = set(files)
    frames = traceback.extract_tb(e.__traceback__)
    keep = [f for f in frames if f.filename in names]
    if frames and (not keep or keep[-1] is not frames[-1]):
        keep.append(frames[-1])
    body = "".join(traceback.StackSummary.from_list(keep).format())
    return (
        "Traceback (most recent call last):\n"
        + body
        + "".join(traceback.format_exception_only(type(e), e))
    )
