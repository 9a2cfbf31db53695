"""The project's root exception and the contract errors, by audience.

Every package subclasses `RivetError` in its own `errors.py`; the CLI maps `UsageError`
(and its subclasses) to exit code 2 ("bad input") and any other `RivetError` to exit code 1
("the work failed").

A `ContractError` is neither by itself: it says a value does not satisfy a contract, not whose
value it was. It is a plain `RivetError` (exit 1), which is right where the value came from
RIVET's own work — a frozen program's plan, a simulator's observation. Where the value is the
user's — a file or an argument the command line read — the boundary that read it says so with
`user_input()`, which re-raises it as `InvalidInputError` (a `UsageError`: exit 2) with the
same message.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from contracts.limits import clip


class RivetError(Exception):
    """Root of every error RIVET raises on purpose."""


class UsageError(RivetError):
    """The user gave bad input (a file, an argument): exit code 2, message names the problem."""


class ContractError(RivetError):
    """A value does not satisfy a contract (exit code 1 unless the value was the user's input:
    see `user_input`).

    Attributes:
        path: JSON path of the offending value, e.g. ``objects[2].pose`` ("" for the root).
        problem: what was expected, e.g. ``rotation is not proper (det = -1.000)``.
        Both are cut to `contracts.limits.CLIP_CHARS` characters (they may quote the value).
    """

    def __init__(self, path: str, problem: str, *, kind: str | None = None) -> None:
        # both may quote the value (a key, a repr): a program's answer can be megabytes
        self.path = clip(path)
        self.problem = clip(problem)
        self.kind = kind
        where = self.path if self.path else "(root)"
        prefix = f"{kind}: " if kind else ""
        super().__init__(f"{prefix}{where}: {self.problem}")


class InvalidInputError(ContractError, UsageError):
    """The user's input does not satisfy a contract: exit code 2, the contract error's message,
    `path`, `problem` and `kind`."""

    @classmethod
    def of(cls, error: ContractError) -> InvalidInputError:
        return cls(error.path, error.problem, kind=error.kind)


@contextmanager
def user_input() -> Iterator[None]:
    """Mark a block as reading the user's input: a `ContractError` raised inside it leaves as
    `InvalidInputError` (exit code 2) with the same message.

        with user_input():
            validate("plan", json.loads(path.read_text()))
    """
    try:
        yield
    except InvalidInputError:
        raise
    except ContractError as e:
        raise InvalidInputError.of(e) from None
