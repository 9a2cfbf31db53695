"""What an in-image entry point receives: the job's loaded draft modules and its inputs.

A job with ``entry="pkg.mod:fn"`` runs ``fn(ctx)`` in the forked child, where `ctx` is an
`EntryContext`; whatever `fn` returns is the job's output (JSON + numpy arrays).

The entry point shares its process with the draft: the draft's import-time code has run before
`fn` is called and could have patched anything in the process. The sandbox keeps the draft away
from the host and owns the verdict, but an output produced in the child is only as trustworthy
as the code that ran there. Checks that must not be forged compare outputs on the host.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import ModuleType
from typing import Any


@dataclass(frozen=True, kw_only=True)
class EntryContext:
    """The loaded job, handed to an entry point.

    Attributes:
        draft: the draft module (``modules[module_name]``).
        modules: every module of the job by name, the draft included.
        function: the function name the job names in the draft.
        inputs: the decoded inputs (JSON values and numpy arrays).
        tmp_dir: a scratch directory private to this job, emptied after it.
    """

    draft: ModuleType
    modules: Mapping[str, ModuleType]
    function: str
    inputs: Mapping[str, Any]
    tmp_dir: str

    @property
    def fn(self) -> Any:
        """The named function of the draft (AttributeError when it is missing)."""
        return getattr(self.draft, self.function)
