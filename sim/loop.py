"""The closed loop: act, look again, and plan again when the world is not what was expected.

The paper executes its plans open loop. `ClosedLoop` runs the same frozen programs — no model
call — around a robot: after each transfer (whether the robot's own sensors said it worked or
not) the robot looks at the scene again from the same camera, `perceive` reads it, and the loop
compares what it sees with what it expected (its belief: the perceived start, then where each
step put its object). Where they differ by more than the domain's scoring tolerance (modulo
symmetry), or a step failed, the belief takes what was seen and `plan` runs again from there to
the goal. The goal is perceived once.

Design rule: the loop knows only the observations it is handed and what its programs return.
It never reads a simulator (a test says so, as for the executor), so a user drives it with
their own robot exactly as a trial does:

    loop = ClosedLoop(domain, runner)              # runner: perceive / relate / plan
    step = loop.begin(start_obs, goal_obs)
    while step is not None:
        ok = my_robot.transfer(step["object"], step["target_pose"])
        step = loop.report(ok=ok, observation=my_robot.observe())
    print(loop.status, loop.reason)                # "done" or "gave_up", and why

Bounded by a `RecoveryBudget` (replans, wall-clock seconds): a loop that would exceed it stops
with status ``gave_up`` and says which bound it met. An object the new observation does not show
(hidden behind another) keeps its believed pose.

A loop with a `judge` (what is wrong with a look's records as an explanation of its
observation; `ProgramPolicy.look_problems` renders them with the set's own `render` and compares
depths, `artifacts.fit`) asks it about the last look before it says done: a part that fell in a
way the programs cannot represent (a cylinder on its side read as standing) makes the loop give
up saying so, instead of ending "done" off the goal.

A loop with a `referee` asks it, before a look moves a belief, whether the image fits the
object better where it was believed: two photos from one camera can share a misreading (a cube
half hidden in a tower, read through a low camera, lands at the same wrong place on both), and
then only the image itself can tell a misread from a move. `ProgramPolicy.look_prefers_belief`
renders both explanations with the set's own `render` (`artifacts.fit.better_explained`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

from contracts import se3
from contracts.limits import clip
from domains import Domain

Status = Literal["running", "done", "gave_up"]
FAR_AGREE_SHARE = 0.25  # two looks that put an object far from its belief agree when they are
# closer to each other than this share of that distance (`ClosedLoop._agree`)


class Programs(Protocol):
    """What the loop calls: a frozen system's functions (`artifacts.runtime.Runner` is one)."""

    def perceive(self, observation: Mapping[str, Any]) -> list[dict]: ...

    def relate(self, records: list[dict]) -> dict: ...

    def plan(self, start_state: dict, goal_state: dict) -> dict: ...


@dataclass(frozen=True, kw_only=True)
class RecoveryBudget:
    """How much recovery the loop may spend before giving up.

    Attributes:
        replans: plans made after the first one.
        seconds: wall-clock time from `begin` (or `adopt`) to the last step handed out [s].
        same_failure: how many times in a row the same step (object and target) may fail
            for the same reason on a scene that looks unchanged: trying it again would only
            repeat what was seen (a part wedged where no grasp fits). Where a look had moved
            the object's belief, the loop first doubts that look (the object is believed where
            it was before, as after a grasp on air) and plans again; it gives up only when
            there is no look left to doubt.
    """

    replans: int = 5
    seconds: float = 300.0
    same_failure: int = 2


@dataclass
class LoopEvent:
    """One thing the loop did: looked, replanned, finished or gave up."""

    kind: Literal["observed", "replanned", "done", "gave_up"]
    step: int  # transfers reported so far
    detail: str = ""

    def to_dict(self) -> dict:
        return {"kind": self.kind, "step": self.step, "detail": self.detail}


@dataclass
class ClosedLoop:
    """Drives a robot with frozen programs until the scene matches the goal or the budget ends.

    Args:
        domain: the task family (its meshes' symmetries and scoring tolerance).
        programs: perceive / relate / plan (`Programs`).
        budget: the recovery budget.
        judge: optional, `judge(observation, records)` → what is wrong with `records` (what
            `perceive` read) as an explanation of `observation`, [] when nothing is; asked of
            the last look before the loop says done.
        referee: optional, `referee(observation, seen, alternative)` → the ids of the objects
            that `alternative` (`seen` with the objects it would move put back where they are
            believed) explains better than `seen` does; those keep their belief.
    """

    domain: Domain
    programs: Programs
    budget: RecoveryBudget = field(default_factory=RecoveryBudget)
    judge: Callable[[Mapping[str, Any], list[dict]], list[str]] | None = None
    referee: Callable[[Mapping[str, Any], list[dict], list[dict]], Sequence[str]] | None = None
    status: Status = "running"
    reason: str | None = None
    events: list[LoopEvent] = field(default_factory=list)
    replans: int = 0
    observations: int = 0
    reported: int = 0
    cause: str | None = None  # the stage a give-up points at, where the loop knows it

    def __post_init__(self) -> None:
        self.belief: dict[str, np.ndarray] = {}
        self.meshes: dict[str, str] = {}
        self.goal: dict | None = None
        self.remaining: list[dict] = []
        self._current: dict | None = None
        self._t0 = time.perf_counter()
        self._repeated: tuple[dict, str, int] | None = None  # (step, failure, times in a row)
        # an object's pose taken from a look over what was believed before: (before, seen)
        self._looked: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._refuted: dict[str, list[np.ndarray]] = {}  # seen poses a grasp found empty
        self._last_look: tuple[Mapping[str, Any], list[dict]] | None = None  # for the judge

    # -- starting -------------------------------------------------------------------------

    def begin(self, start_obs: Mapping[str, Any], goal_obs: Mapping[str, Any]) -> dict | None:
        """Perceive both observations, plan, and hand out the first step (None: nothing to do,
        or the plan is infeasible — see `status`)."""
        start = self._state(self.programs.perceive(start_obs))
        goal = self._state(self.programs.perceive(goal_obs))
        return self.adopt(start, goal, self.programs.plan(start, goal))

    def adopt(self, start_state: Mapping, goal_state: Mapping, plan: Mapping) -> dict | None:
        """Start from states and a plan already made (a trial's open-loop policy output)."""
        self._t0 = time.perf_counter()
        self.goal = dict(goal_state)
        self._believe(start_state.get("objects", []))
        for r in goal_state.get("objects", []):
            if isinstance(r, Mapping) and "id" in r and "mesh" in r:
                self.meshes.setdefault(str(r["id"]), str(r["mesh"]))
        return self._follow(plan, "the first plan")

    # -- after each transfer ------------------------------------------------------------------

    def report(self, *, ok: bool, observation: Mapping[str, Any], failure: str | None = None,
               missed: bool = False,
               look_again: Callable[[], Mapping[str, Any]] | None = None) -> dict | None:  # fmt: skip
        """The robot carried out the step last handed out (`ok`: its own sensors saw no
        failure; `failure`: what they said; `missed`: the hand closed on nothing where the
        object was believed) and looked again: the next step, or None when the loop has ended
        (`status`).

        A look can be wrong too (a part half hidden, a camera `perceive` reads poorly). With
        `look_again` (how to take another observation of the scene as it now is), a look that
        shows an object off its believed pose is checked by a second one, and only what both
        show, within the scoring tolerance of each other, is believed: a poorly read part lands
        somewhere else on each look, a moved part stays where it was moved. And when the hand
        closes on nothing where a look had moved an object's belief, that look is refuted —
        the object is believed where it was before, and a later look that shows it at the
        refuted pose again is not believed."""
        if self.status != "running" or self._current is None:
            raise RuntimeError("report() follows a step handed out by begin/adopt/report")
        step, self._current = self._current, None
        self.reported += 1
        oid = str(step["object"])
        if ok:
            target = np.asarray(step["target_pose"], float)
            self.belief[oid] = target
            self._looked.pop(oid, None)  # placed: the hand knows where it is
            self._refuted[oid] = [
                T for T in self._refuted.get(oid, []) if not self._near(T, target)
            ]
        recalled = not ok and missed and self._recall(oid)  # before the new look is judged
        seen = self.programs.perceive(observation)
        self.observations += 1
        self._last_look = (observation, seen)
        unconfirmed: list[str] = []
        if look_again is not None and any(self._away(r) is not None for r in seen or []):
            again = self.programs.perceive(look_again())
            self.observations += 1
            seen, unconfirmed = self._confirmed(seen, again)
        seen, refereed = self._refereed(observation, seen)
        off = self._differences(seen)
        times = 0  # how many times in a row this step failed this way on an unchanged scene
        if not ok and not off and not recalled:
            times = self._same_failure(step, failure or "")
        # every step where a look put the object fails the same way: doubt that look first
        doubted = times >= self.budget.same_failure and self._recall(oid)
        if doubted:
            self._repeated = None
        self.events.append(LoopEvent(
            kind="observed", step=self.reported,
            detail=("as expected" if not off and ok and not unconfirmed and not refereed else
                    "; ".join(([f"the step failed: {clip(failure or 'no reason', 160)}"]
                               if not ok else []) + off[:4] +
                              ([f"{oid} was not where a look had put it: believed where it "
                                "was before"] if recalled else []) +
                              ([f"{oid} failed {times} times in a row where a look had put it:"
                                " believed where it was before"] if doubted else []) +
                              ([f"a second look did not confirm {', '.join(unconfirmed[:4])}: "
                                "believed where it was"] if unconfirmed else []) +
                              ([f"the image fits {', '.join(refereed[:4])} better where believed:"
                                " believed there"] if refereed else []))),
        ))  # fmt: skip
        if ok and not off:
            self._repeated = None
            return self._next()
        if times >= self.budget.same_failure and not doubted:
            return self._stop(f"step {self.reported} ({oid}) failed {times} times in a row "
                              f"the same way on a scene that did not change: "
                              f"{clip(failure or 'no reason', 160)}")  # fmt: skip
        if ok or off or recalled:
            self._repeated = None
        if self.replans >= self.budget.replans:
            return self._stop(f"the recovery budget of {self.budget.replans} replans is spent "
                                 f"({'; '.join(off[:2]) or 'a step failed'})")  # fmt: skip
        if time.perf_counter() - self._t0 > self.budget.seconds:
            return self._stop(f"the recovery budget of {self.budget.seconds:g} s is spent")
        self.replans += 1
        assert self.goal is not None
        state = self._state(self._records())
        return self._follow(self.programs.plan(state, self.goal), f"replan {self.replans}")

    # -- inside -------------------------------------------------------------------------------

    def _symmetries(self, mesh: str | None) -> list[np.ndarray]:
        if mesh in self.domain.mesh_specs:
            return list(self.domain.symmetries(mesh))
        return [np.eye(4)]

    def _near(self, a: np.ndarray, b: np.ndarray, mesh: str | None = None) -> bool:
        """Whether two poses agree within the domain's scoring tolerance (modulo `mesh`'s
        symmetries when given)."""
        tol = self.domain.tolerance
        return se3.within_tolerance(a, b, trans_tol=tol.translation, rot_tol=tol.rotation,
                                    symmetries=self._symmetries(mesh))  # fmt: skip

    def _recall(self, oid: str) -> bool:
        """Undo the look that moved `oid`'s belief (a grasp there found nothing): True when
        there was one."""
        looked = self._looked.pop(oid, None)
        if looked is None:
            return False
        before, seen = looked
        self._refuted.setdefault(oid, []).append(seen)
        self.belief[oid] = before
        return True

    def _same_failure(self, step: dict, failure: str) -> int:
        """How many times in a row `step` has now failed with `failure`, the scene unchanged."""
        last = self._repeated
        again = (
            last is not None
            and last[0]["object"] == step["object"]
            and last[1] == failure
            and self._near(last[0]["target_pose"], step["target_pose"])
        )
        times = last[2] + 1 if again and last is not None else 1
        self._repeated = (step, failure, times)
        return times

    def _state(self, records: list[dict]) -> dict:
        return {"objects": records, "relations": self.programs.relate(records)}

    def _believe(self, records: Any) -> None:
        for r in records or []:
            try:
                T = se3.as_matrix(r["pose"])
            except (KeyError, TypeError, ValueError):
                continue
            if se3.is_rigid(T, tol=1e-3):
                self.belief[str(r["id"])] = T
                self.meshes[str(r["id"])] = str(r.get("mesh", ""))

    def _records(self) -> list[dict]:
        return [
            {"id": oid, "mesh": self.meshes[oid], "pose": T.tolist()}
            for oid, T in self.belief.items()
        ]

    def _away(self, r: Any) -> tuple[str, np.ndarray, str] | None:
        """(id, pose, mesh) of a seen record that differs from the belief beyond the scoring
        tolerance (an object not believed at all included), and not at a pose a grasp found
        empty; None otherwise."""
        try:
            oid, T = str(r["id"]), se3.as_matrix(r["pose"])
        except (KeyError, TypeError, ValueError):
            return None
        if not se3.is_rigid(T, tol=1e-3):
            return None
        mesh = self.meshes.get(oid) or str(r.get("mesh", ""))
        before = self.belief.get(oid)
        if before is not None and (
            self._near(T, before, mesh)
            or any(self._near(T, bad, mesh) for bad in self._refuted.get(oid, []))
        ):
            return None
        return oid, T, mesh

    def _confirmed(self, seen: list[dict], again: list[dict]) -> tuple[list[dict], list[str]]:
        """The records of `seen` that are as believed, or that `again` shows within the scoring
        tolerance of where `seen` does; and, for the others, what the second look showed."""
        second: dict[str, np.ndarray] = {}
        for r in again or []:
            try:
                second[str(r["id"])] = se3.as_matrix(r["pose"])
            except (KeyError, TypeError, ValueError):
                continue
        kept, unconfirmed = [], []
        for r in seen or []:
            away = self._away(r)
            if away is None:
                kept.append(r)
                continue
            oid, T, mesh = away
            T2 = second.get(oid)
            if T2 is not None and self._agree(oid, T, T2, mesh):
                kept.append(r)
            elif T2 is None:
                unconfirmed.append(f"{oid} (not shown)")
            else:
                t, _ = se3.pose_error(T2, T, self._symmetries(mesh))
                unconfirmed.append(f"{oid} ({1000 * t:.0f} mm from the first)")
        return kept, unconfirmed

    def _refereed(self, observation: Mapping[str, Any], seen: Any) -> tuple[Any, list[str]]:
        """`seen` without the records the referee finds better explained at their believed
        poses, and those records' ids (nothing changes without a referee, or when the look
        moves nothing believed)."""
        if self.referee is None or not isinstance(seen, list):
            return seen, []
        moved: dict[str, np.ndarray] = {}
        for r in seen:
            away = self._away(r)
            if away is not None and away[0] in self.belief:
                moved[away[0]] = self.belief[away[0]]
        if not moved:
            return seen, []

        def oid(r: Any) -> str:
            return str(r.get("id")) if isinstance(r, Mapping) else ""

        alternative = [
            {**r, "pose": moved[oid(r)].tolist()} if oid(r) in moved else r for r in seen
        ]
        better = {str(i) for i in self.referee(observation, seen, alternative)} & moved.keys()
        return [r for r in seen if oid(r) not in better], sorted(better)

    def _agree(self, oid: str, T: np.ndarray, T2: np.ndarray, mesh: str) -> bool:
        """Whether two looks agree on an object: within the scoring tolerance of each other,
        or — when both put it far from its belief — their positions closer to each other than
        `FAR_AGREE_SHARE` of that distance, whatever their turns (a part half hidden behind
        another reads a few millimetres and degrees differently on each photo, but a part 18 cm
        from where it was believed has moved)."""
        if self._near(T, T2, mesh):
            return True
        before = self.belief.get(oid)
        if before is None:
            return False
        apart = float(np.linalg.norm(T[:3, 3] - T2[:3, 3]))
        moved = min(float(np.linalg.norm(X[:3, 3] - before[:3, 3])) for X in (T, T2))
        return moved > self.domain.tolerance.translation and apart <= FAR_AGREE_SHARE * moved

    def _differences(self, seen: list[dict]) -> list[str]:
        """What the observation shows otherwise than believed, beyond the scoring tolerance;
        the belief takes what was seen there. Unseen objects keep their believed pose, and so
        do objects seen where a grasp already found nothing."""
        off = []
        for r in seen or []:
            away = self._away(r)
            if away is None:
                continue  # as believed, or seen where a grasp already found nothing
            oid, T, mesh = away
            before = self.belief.get(oid)
            if before is None:
                off.append(f"{oid} seen, not believed")
            else:
                t, _ = se3.pose_error(T, before, self._symmetries(mesh))
                off.append(f"{oid} is {1000 * t:.0f} mm from where it was believed")
                earlier = self._looked.get(oid)
                self._looked[oid] = (earlier[0] if earlier else before, T)
            self.belief[oid] = T
            self.meshes[oid] = mesh
        return off

    def _follow(self, plan: Any, which: str) -> dict | None:
        if not isinstance(plan, Mapping) or plan.get("status") != "ok":
            why = plan.get("reason") if isinstance(plan, Mapping) else "not a plan"
            return self._stop(f"{which} says infeasible: {clip(str(why), 200)}")
        self.remaining = [
            {"object": str(s["object"]), "target_pose": np.asarray(s["target_pose"], float)}
            for s in plan.get("steps", [])
        ]
        if which != "the first plan":
            self.events.append(LoopEvent(kind="replanned", step=self.reported,
                                         detail=f"{which}: {len(self.remaining)} steps"))  # fmt: skip
        return self._next()

    def _next(self) -> dict | None:
        if not self.remaining:
            problems = self._misfit()
            if problems:
                self.cause = "perception"
                return self._stop(
                    f"the last look does not fit what perceive read ({clip(problems[0], 160)}):"
                    " a part may rest in a way the programs cannot represent"
                )
            self.status = "done"
            self.events.append(LoopEvent(kind="done", step=self.reported))
            return None
        if time.perf_counter() - self._t0 > self.budget.seconds:
            return self._stop(f"the recovery budget of {self.budget.seconds:g} s is spent")
        self._current = self.remaining.pop(0)
        return self._current

    def _misfit(self) -> list[str]:
        """The judge's problems with the last look (none without a judge or a look)."""
        if self.judge is None or self._last_look is None:
            return []
        observation, seen = self._last_look
        return list(self.judge(observation, seen if isinstance(seen, list) else []))

    def _stop(self, reason: str) -> dict | None:
        self.give_up(reason)
        return None

    def give_up(self, reason: str) -> None:
        """End the loop with status ``gave_up`` and `reason` (also for its driver: a deadline)."""
        self.status, self.reason = "gave_up", reason
        self.events.append(LoopEvent(kind="gave_up", step=self.reported, detail=reason))

    def to_dict(self) -> dict:
        return {
            "status": self.status,
            "reason": self.reason,
            "replans": self.replans,
            "observations": self.observations,
            "transfers": self.reported,
            "cause": self.cause,
            "events": [e.to_dict() for e in self.events],
        }
