"""The thin runtime: load a domain's frozen programs by hash and run perceive → relate → plan.

Design rule: frozen programs are model-written code. They run in a sandbox session (Docker by
default; the local backend when asked for by name), never in the caller's process, so nothing
the caller holds — a trial's ground truth, the user's environment — is in their reach; they get
the observation, the meshes and the camera, and nothing else. No model calls, and a file whose
hash does not match its manifest is refused, with the file named. What a program returns is
counted before anything reads it (`contracts.limits`: records within the domain's catalogue,
edges within what its objects allow, plan steps within the contract's cap), so a program's
answer cannot make the next program's input, or the robot's plan, grow without bound.

    system = load("cubes")
    with system.runner(executor) as run:
        plan = run.solve(start_obs, goal_obs)
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

from artifacts.errors import ArtifactError, ProgramFailed
from artifacts.store import verify
from contracts.functions import FUNCTIONS, authoring_order
from contracts.limits import clip, count_problem
from sandbox import MESHES, CallReport, Executor, Program

CALL_TIMEOUT_S = 30.0  # [s] one call of a frozen function (its checks held it to far less)


@dataclass
class System:
    """A domain's frozen programs (their sources), ready to be loaded into a sandbox.

    Attributes:
        objects: the domain's catalogue size, which bounds what the programs may return
            (`contracts.limits`; None: only the plan's step cap applies).
    """

    domain: str
    manifest: dict[str, Any]
    sources: dict[str, str]
    meshes: dict[str, Any] = field(default_factory=dict)
    objects: int | None = None

    def program(self) -> Program:
        ordered = {name: self.sources[name] for name in authoring_order() if name in self.sources}
        return Program(modules=ordered, meshes=self.meshes)

    def runner(self, executor: Executor, *, timeout_s: float = CALL_TIMEOUT_S) -> Runner:
        """The programs loaded in a session of `executor` (close it, or use `with`)."""
        return Runner(self, executor, timeout_s=timeout_s)


class Runner:
    """A `System` loaded in one sandbox session; its functions called there.

    Raises `ProgramFailed` (the work failed: exit code 1) when a program does not load, raises,
    overruns its time or returns what cannot be read.
    """

    def __init__(self, system: System, executor: Executor, *, timeout_s: float) -> None:
        self.system = system
        self.timeout_s = timeout_s
        self.session = executor.open_session(system.program(), load_timeout_s=120.0)
        self.timings: dict[str, float] = {}
        self.cpu: dict[str, float] = {}
        self.last_states: tuple[dict, dict] | None = None
        if not self.session.load.ok:
            self.session.close()
            raise ProgramFailed(f"the frozen programs do not load: {_why(self.session.load)}")

    def __enter__(self) -> Runner:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        self.session.close()

    def _call(self, name: str, *args: Any) -> tuple[Any, CallReport]:
        got = self.session.call(name, name, *args, timeout_s=self.timeout_s)
        if not got.ok:
            raise ProgramFailed(f"the frozen `{name}` {_why(got)}", function=name)
        problem = count_problem(name, got.value, objects=self.system.objects)
        if problem is not None:
            raise ProgramFailed(
                f"the frozen `{name}` returned a value that cannot be used ({problem})",
                function=name,
            )
        return got.value, got

    def render(self, records: list[dict], camera: Mapping[str, Any]) -> dict:
        """The frozen `render` of `records` from `camera`: {"rgb", "depth", "mask"}."""
        value, _ = self._call("render", records, MESHES, camera)
        return value

    def perceive(self, observation: Mapping[str, Any]) -> list[dict]:
        obs = {k: observation[k] for k in ("rgb", "depth", "camera")}
        value, _ = self._call("perceive", obs, MESHES, obs["camera"])
        return value

    def relate(self, records: list[dict]) -> dict:
        value, _ = self._call("relate", records, MESHES)
        return value

    def plan(self, start_state: dict, goal_state: dict) -> dict:
        value, _ = self._call("plan", start_state, goal_state, MESHES)
        return value

    def solve(self, start_obs: Mapping[str, Any], goal_obs: Mapping[str, Any]) -> dict:
        """perceive both observations, relate both, plan; per-stage wall and CPU times (of the
        calls themselves, measured outside the programs) in `timings` and `cpu`."""
        wall: dict[str, float] = dict.fromkeys(("perceive", "relate", "plan"), 0.0)
        cpu: dict[str, float] = dict(wall)
        t0 = time.perf_counter()

        def call(name: str, *args: Any) -> Any:
            value, got = self._call(name, *args)
            wall[name] += got.seconds
            cpu[name] += got.cpu_seconds
            return value

        def obs(o: Mapping[str, Any]) -> dict[str, Any]:
            return {k: o[k] for k in ("rgb", "depth", "camera")}

        start_obs, goal_obs = obs(start_obs), obs(goal_obs)
        start_records = call("perceive", start_obs, MESHES, start_obs["camera"])
        goal_records = call("perceive", goal_obs, MESHES, goal_obs["camera"])
        start = {"objects": start_records, "relations": call("relate", start_records, MESHES)}
        goal = {"objects": goal_records, "relations": call("relate", goal_records, MESHES)}
        result = call("plan", start, goal, MESHES)
        wall["total"] = sum(wall.values())
        cpu["total"] = sum(cpu.values())
        wall["round_trip"] = time.perf_counter() - t0  # with the sandbox's transfers
        self.timings, self.cpu = wall, cpu
        self.last_states = (start, goal)
        return result


def _why(report: CallReport) -> str:
    if report.verdict == "exception" and report.exception is not None:
        return f"raised {clip(report.exception.type, 100)}: {clip(report.exception.message)}"
    if report.verdict == "timeout":
        return "did not return in time"
    return f"failed ({report.verdict}: {clip(report.detail)})"


def read_programs(folder: Path) -> dict[str, str]:
    """The four sources of a programs folder (`render.py`, …), unverified (no manifest)."""
    sources = {}
    for name in FUNCTIONS:
        path = Path(folder) / f"{name}.py"
        if not path.is_file():
            raise ArtifactError(f"{folder}: {path.name} is missing")
        sources[name] = path.read_text()
    return sources


def load(
    domain: str,
    root: Path | None = None,
    *,
    meshes: dict[str, Any] | None = None,
    objects: int | None = None,
) -> System:
    """Verify `artifacts/<domain>/` against its manifest; the system, ready for a sandbox.

    `meshes` and `objects` (the catalogue's size) default to the registered domain's; given
    meshes and no `objects`, only the plan's step cap bounds what the programs return."""
    manifest, sources = verify(domain, root)
    meshes, objects = _of_domain(domain, meshes, objects)
    return System(
        domain=domain, manifest=manifest, sources=dict(sources), meshes=meshes, objects=objects
    )


def from_folder(
    domain: str,
    folder: Path,
    *,
    meshes: dict[str, Any] | None = None,
    objects: int | None = None,
) -> System:
    """A system from a programs folder (no manifest: e.g. an authoring run's programs)."""
    meshes, objects = _of_domain(domain, meshes, objects)
    return System(
        domain=domain,
        manifest={},
        sources=read_programs(folder),
        meshes=meshes,
        objects=objects,
    )


def _of_domain(
    domain: str, meshes: dict[str, Any] | None, objects: int | None
) -> tuple[dict[str, Any], int | None]:
    if meshes is not None:
        return meshes, objects
    import domains

    dom = domains.load(domain)
    return dom.meshes(), len(dom.objects) if objects is None else objects
