"""The thin runtime: load a domain's frozen programs by hash and run perceive → relate → plan.

Imports neither the model SDK nor Docker: frozen programs were checked in the sandbox when
they were authored and run in-process here. A file whose hash does not match its manifest is
refused, with the file named.
"""

from __future__ import annotations

import importlib.util
import sys
import time
import types
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from artifacts.errors import ArtifactError
from artifacts.store import verify
from contracts.functions import authoring_order


@dataclass
class System:
    """A domain's frozen programs, ready to run on observations."""

    domain: str
    manifest: dict[str, Any]
    modules: dict[str, types.ModuleType]
    meshes: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)

    def _fn(self, name: str) -> Callable[..., Any]:
        return getattr(self.modules[name], name)

    def render(self, records, meshes, camera):
        return self._fn("render")(records, meshes, camera)

    def perceive(self, observation: dict) -> list[dict]:
        return self._fn("perceive")(observation, self.meshes, observation["camera"])

    def relate(self, records: list[dict]) -> dict:
        return self._fn("relate")(records, self.meshes)

    def plan(self, start_state: dict, goal_state: dict) -> dict:
        return self._fn("plan")(start_state, goal_state, self.meshes)

    @property
    def relations_vocabulary(self) -> dict[str, str]:
        return dict(getattr(self.modules["relate"], "RELATIONS", {}))

    def solve(self, start_obs: dict, goal_obs: dict) -> dict:
        """perceive both observations, relate both, plan; per-stage timings in `self.timings`."""
        t = time.perf_counter()
        start_records = self.perceive(start_obs)
        goal_records = self.perceive(goal_obs)
        t1 = time.perf_counter()
        start = {"objects": start_records, "relations": self.relate(start_records)}
        goal = {"objects": goal_records, "relations": self.relate(goal_records)}
        t2 = time.perf_counter()
        result = self.plan(start, goal)
        t3 = time.perf_counter()
        self.timings = {"perceive": t1 - t, "relate": t2 - t1, "plan": t3 - t2, "total": t3 - t}
        self.last_states = (start, goal)
        return result


def load_modules(sources: dict[str, str], *, origin: str) -> dict[str, types.ModuleType]:
    """Execute the sources in DAG order; each is importable by the next under its own name."""
    modules: dict[str, types.ModuleType] = {}
    saved = {name: sys.modules.get(name) for name in sources}
    try:
        for name in authoring_order():
            if name not in sources:
                continue
            spec = importlib.util.spec_from_loader(name, loader=None, origin=f"{origin}/{name}.py")
            assert spec is not None
            module = importlib.util.module_from_spec(spec)
            module.__file__ = f"{origin}/{name}.py"
            sys.modules[name] = module  # `from render import render` inside later programs
            try:
                exec(compile(sources[name], module.__file__, "exec"), module.__dict__)
            except Exception as e:
                raise ArtifactError(
                    f"{module.__file__} failed to load: {type(e).__name__}: {e}"
                ) from e
            if not callable(getattr(module, name, None)):
                raise ArtifactError(f"{module.__file__} defines no function '{name}'")
            modules[name] = module
    finally:
        for name, old in saved.items():
            if old is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = old
    return modules


def load(domain: str, root: Path | None = None, *, meshes: dict[str, Any] | None = None) -> System:
    """Verify `artifacts/<domain>/` against its manifest and load the programs in-process."""
    manifest, sources = verify(domain, root)
    modules = load_modules(sources, origin=f"artifacts/{domain}")
    if meshes is None:
        import domains

        meshes = domains.load(domain).meshes()
    return System(domain=domain, manifest=manifest, modules=modules, meshes=meshes)
