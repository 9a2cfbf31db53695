"""The policy the trials run with frozen (or any) programs: observations in, plan out.

Design rule: the programs run in a sandbox session of their own (`artifacts.runtime.Runner`):
the trial's process keeps the instance, the programs see only the two observations (with the
calibrated camera), the meshes, and what they return to each other. The session stays open
across trials, so the programs are loaded once per worker.

Kinds: `oracle`, `artifacts [ROOT]`, `programs DIR`, and `run RUN_DIR`: the final programs of
one authoring run (`RUN_DIR/frozen/`, as `rivet author` writes it). A reliability study
(`rivet eval D --policy runs RUNS_DIR`) is one `run` policy per run that `find_runs` lists.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from artifacts import jsonl
from artifacts.runtime import Runner, System, from_folder, load
from contracts.errors import UsageError

PolicySpec = tuple[str, str | None]  # ("oracle" | "programs" | "artifacts" | "run", folder or None)


class ProgramPolicy:
    """A `System`'s programs as a trial policy, in a sandbox session."""

    oracle = False

    def __init__(
        self, system: System, name: str, *, sandbox: str = "docker", fit: bool = False
    ) -> None:
        import sandbox as sb

        self.system = system
        self.name = name
        self.fit = fit  # judge each perceived state's fit (`artifacts.fit`), about 0.5 s a trial
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
        fit = None
        if self.fit:
            t = time.perf_counter()
            fit = {
                side: _fit(domain, obs, state, run)
                for side, obs, state in (("start", start_obs, start), ("goal", goal_obs, goal))
            }
            timings["fit"] = time.perf_counter() - t
        return PolicyOutput(plan=plan, start_state=start, goal_state=goal, timings=timings, fit=fit)

    def look_problems(self, domain: Any, observation: dict, records: list[dict]) -> list[str]:
        """What `artifacts.fit` finds wrong with `records` as an explanation of `observation`
        (the closed loop's judge, `sim.loop`): its problems, and a part standing where nothing
        was perceived (`SceneFit.loose_part`); [] when they fit, or when the fit cannot be
        judged (no refusal on a failing `render`)."""
        fit = _fit(domain, observation, {"objects": records}, self.runner())
        if fit["ok"] is None:
            return []
        return [*fit["problems"], *([fit["loose_part"]] if fit.get("loose_part") else [])]

    def look_prefers_belief(
        self, domain: Any, observation: dict, seen: list[dict], alternative: list[dict]
    ) -> list[str]:
        """The ids of the objects `alternative` (`seen` with some objects at their believed
        poses) explains `observation` better than `seen` does (`artifacts.fit.better_explained`,
        the closed loop's referee); none when the fit cannot be judged."""
        from artifacts.fit import better_explained

        try:
            return better_explained(domain, observation, seen, alternative, self.runner().render)
        except Exception:  # the frozen render's fault: no preference
            return []

    def programs(self) -> Runner:
        """The programs' session, for the closed loop (`sim.loop`): perceive, relate, plan."""
        return self.runner()

    def reset(self) -> None:
        if self._runner is not None:
            self._runner.close()
            self._runner = None

    def close(self) -> None:
        self.reset()
        self.executor.close()


def _fit(domain: Any, observation: dict, state: dict | None, run: Runner) -> dict:
    """What `rivet solve` judges by (`artifacts.fit`), for the trial's JSON: how well the
    perceived state explains the observation."""
    from artifacts.fit import scene_fit

    if state is None:
        return {"ok": None, "problems": ["nothing was perceived"]}
    try:
        return scene_fit(domain, observation, state["objects"], run.render).to_dict()
    except Exception as e:  # the frozen render's fault: no judgement, said so
        return {"ok": None, "problems": [f"the fit cannot be judged: {type(e).__name__}: {e}"]}


def make_policy(
    domain: str, spec: PolicySpec, *, sandbox: str = "docker", fit: bool = False
) -> Any:
    """The policy a spec names: the oracle, the frozen artifacts, or a programs folder.
    `fit`: a programs policy also judges each perceived state's fit (`artifacts.fit`)."""
    kind, folder = spec
    if kind == "oracle":
        from sim.trials import OraclePolicy

        return OraclePolicy()
    if kind == "artifacts":
        return ProgramPolicy(
            load(domain, Path(folder) if folder else None), "artifacts", sandbox=sandbox, fit=fit
        )
    if kind == "programs":
        if folder is None:
            raise UsageError("--policy programs needs a folder")
        return ProgramPolicy(
            from_folder(domain, Path(folder)), f"programs {folder}", sandbox=sandbox, fit=fit
        )
    if kind == "run":
        if folder is None:
            raise UsageError("policy 'run' needs an authoring run's folder")
        programs = Path(folder) / "frozen"
        return ProgramPolicy(
            from_folder(domain, programs), f"run {folder}", sandbox=sandbox, fit=fit
        )
    if kind == "runs":
        raise UsageError(
            "'runs DIR' is a study, not one policy: `rivet eval DOMAIN --policy runs DIR` "
            "evaluates each run under DIR with policy 'run RUN_DIR'"
        )
    raise UsageError(f"unknown policy {kind!r}; known: oracle, artifacts, programs DIR, run DIR")


# --- authoring runs, for reliability studies ---------------------------------------------------


@dataclass(frozen=True)
class AuthoringRunFolder:
    """One folder of `rivet author D --runs N --runs-dir RUNS_DIR`: RUNS_DIR/D/<stamp>/.

    Attributes:
        name: the folder relative to the runs folder searched (e.g. `cubes/20260101-120000`).
        finished: the run's journal says it finished and every function is in `frozen/`.
        reason: why the run did not finish (None when it did).
        started: the run made a model call (or froze something); a folder with no journal, or
            whose journal stops before any call (its options or credentials were refused),
            is a run that never started: not an authoring attempt, so not a failed one.
    """

    name: str
    path: Path
    finished: bool
    reason: str | None = None
    started: bool = True

    @property
    def policy(self) -> PolicySpec | None:
        """The policy of the run's final programs (None: the run produced none)."""
        return ("run", str(self.path)) if self.finished else None


def find_runs(domain: str, runs_dir: Path) -> list[AuthoringRunFolder]:
    """Every authoring run of `domain` under `runs_dir`, finished or not, in name order.

    `runs_dir` is what `--runs-dir` was (its `<domain>/` holds the runs; with `--ray`, each
    `ray-k/<domain>/` does), or that `<domain>/` folder itself. Every sub-folder there is a
    run: one with no journal, or whose journal did not finish, is a failed run with the reason.
    """
    if not runs_dir.is_dir():
        raise UsageError(f"--policy runs {runs_dir}: no such folder")
    parents = [runs_dir / domain, *sorted(runs_dir.glob(f"*/{domain}"))]
    if runs_dir.name == domain:
        parents.append(runs_dir)
    folders = sorted(
        {
            c
            for parent in parents
            if parent.is_dir()
            for c in parent.iterdir()
            if c.is_dir() and not c.name.startswith(".")
        }
    )
    if not folders:
        raise UsageError(
            f"--policy runs {runs_dir}: no authoring runs of {domain} there (expected "
            f"{runs_dir}/{domain}/<run>/, as `rivet author {domain} --runs N --runs-dir "
            f"{runs_dir}` writes)"
        )
    return [_run_folder(domain, runs_dir, f) for f in folders]


def _run_folder(domain: str, runs_dir: Path, path: Path) -> AuthoringRunFolder:
    from contracts.functions import FUNCTIONS

    name = str(path.relative_to(runs_dir))

    def failed(reason: str, *, started: bool = True) -> AuthoringRunFolder:
        return AuthoringRunFolder(name, path, False, reason, started)

    journal = path / "journal.jsonl"
    if not journal.is_file():
        return failed("no journal.jsonl: the run never started", started=False)
    events = jsonl.read(journal)
    started = next((e for e in events if e.get("event") == "started"), None)
    if started is not None:
        other = started.get("config", {}).get("domain")
        if other not in (None, domain):
            return failed(f"a run of {other}, not {domain}")
    if not any(e.get("event") not in ("started",) for e in events):
        return failed("the run never started: its journal holds no call", started=False)
    frozen = [e["function"] for e in events if e.get("event") == "frozen"]
    if not any(e.get("event") == "finished" for e in events):
        last = events[-1] if events else {}
        kind = last.get("event", "nothing")
        at = (
            f" {last['function']} attempt {last['attempt']}"
            if "function" in last and "attempt" in last
            else f" {last['function']}"
            if "function" in last
            else ""
        )
        if kind == "exhausted":
            why = f"authoring exhausted: {last.get('function')} failed all {last.get('attempts')} attempts"
        elif kind == "call_failed":
            why = f"the model call for{at} failed: {str(last.get('error', ''))[:300]}"
        elif kind == "refused":
            why = f"the budget refused the call for{at}"
        else:
            why = f"did not finish (killed?): the journal ends with '{kind}'{at}"
        done = ", ".join(frozen) if frozen else "none"
        return failed(f"{why} (frozen: {done})")
    missing = [f for f in FUNCTIONS if not (path / "frozen" / f"{f}.py").is_file()]
    if missing:
        return failed(f"finished, but frozen/ lacks {', '.join(f + '.py' for f in missing)}")
    return AuthoringRunFolder(name, path, True)
