"""The project's root exception and the contract error.

Every package subclasses `RivetError` in its own `errors.py`; the CLI maps `UsageError`
(and its subclasses) to exit code 2 and any other `RivetError` to exit code 1.
"""

from __future__ import annotations


class RivetError(Exception):
    """Root of every error RIVET raises on purpose."""


class UsageError(RivetError):
    """The user gave bad input (a file, an argument): exit code 2, message names the problem."""


class ContractError(UsageError):
    """A value does not satisfy a contract.

    Attributes:
        path: JSON path of the offending value, e.g. ``objects[2].pose`` ("" for the root).
        problem: what was expected, e.g. ``rotation is not proper (det = -1.000)``.
    """

    def __init__(self, path: str, problem: str, *, kind: str | None = None) -> None:
        self.path = path
        self.problem = problem
        self.kind = kind
        where = path if path else "(root)"
        prefix = f"{kind}: " if kind else ""
        super().__init__(f"{prefix}{where}: {problem}")
