"""The policy the trials run with frozen (or any) programs: observations in, plan out.

Design rule: the programs run in a sandbox session of their own (`artifacts.runtime.Runner`):
the trial's process keeps the instance, the programs see only the two observations (with the
calibrated camera), the meshes, and what they return to each other. The session stays open
across trials, so the programs are loaded once per worker.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from artifacts.runtime import Runner, System, from_folder, load
from contracts.errors import UsageError

PolicySpec = tuple[str, str | None]  # ("oracle" | "programs" | "artifacts", folder or None)


class ProgramPolicy:
    """A `System`'s programs as a trial policy, in a sandbox session."""

    oracle = False

    def __init__(self, system: System, name: str, *, sandbox: str = "docker") -> None:
        import sandbox as sb

        self.system = system
        self.name = name
        self.executor = sb.open_executor(sandbox, **({"quiet": True} if sandbox == "local" else {}))
        self._runner: Runner | None = None

    def runner(self) -> Runner:
        if self._runner is None:
            self._runner = self.system.runner(self.executor)
        return self._runner

    def solve(self, domain: Any, start_obs: dict, goal_obs: dict):
        from sim.trials import PolicyOutput

        run = self.runner()
        try:
            plan = run.solve(start_obs, goal_obs)
        except Exception:
            self.reset()  # a program that failed may have ended its session
            raise
        start, goal = run.last_states or (None, None)
        timings = dict(run.timings)
        timings.update({f"cpu_{k}": v for k, v in run.cpu.items()})
        return PolicyOutput(plan=plan, start_state=start, goal_state=goal, timings=timings)

    def reset(self) -> None:
        if self._runner is not None:
            self._runner.close()
            self._runner = None

    def close(self) -> None:
        self.reset()
        self.executor.close()


def make_policy(domain: str, spec: PolicySpec, *, sandbox: str = "docker") -> Any:
    """The policy a spec names: the oracle, the frozen artifacts, or a programs folder."""
    kind, folder = spec
    if kind == "oracle":
        from sim.trials import OraclePolicy

        return OraclePolicy()
    if kind == "artifacts":
        return ProgramPolicy(load(domain, Path(folder) if folder else None), "artifacts", sandbox=sandbox)
    if kind == "programs":
        if folder is None:
            raise UsageError("--policy programs needs a folder")
        return ProgramPolicy(from_folder(domain, Path(folder)), f"programs {folder}", sandbox=sandbox)
    raise UsageError(f"unknown policy {kind!r}; known: oracle, artifacts, programs DIR")
