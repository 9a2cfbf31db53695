"""Faults injected into a trial: the world (or the robot's perception) misbehaving once.

Design rule: a fault is the world acting, so it may read and write the simulator's state (an
object pushed, a part moved by a person); it never informs the robot. The executor and the
closed loop learn of a fault only as a real robot would: through the gripper's signals and the
next observation. Each trial gets at most one fault, drawn from the names asked for and placed
at a moment drawn from the trial's name (`draw`), so a run is repeatable.

The faults (`FAULTS`), each at "the k-th transfer" of the trial (k drawn below the initial
plan's length):

- ``slip``:  the hand lets the part go as the transfer starts (the jaws open): it falls from
  the transfer height, somewhere between its pick and its place.
- ``push``:  right after the k-th part is placed, it is pushed 20–40 mm sideways (kinematically,
  to a place where it overlaps nothing; what it leaves unsupported falls).
- ``move``:  after the k-th transfer a person moves another part, one that holds nothing up and
  is not the one just placed, to a free place on the table 60–120 mm away, turned.
- ``bias``:  perception puts one part of the start 15 mm off (in the robot's belief, after the
  programs' output is scored: the programs are not at fault).
- ``skip``:  the robot silently skips the k-th transfer (it reports it done).

`Fault.record` says what happened and when (the sim time, the step, the object, the
displacement); a fault whose moment never came (the trial ended first) says so. A fault that
moves parts (slip, push, move) also says, once they have come to rest (`SETTLE_S` later, or
when the trial ends), which parts it left on another face than they rested on before
(`toppled`): a pillar on its side, a roof fallen off its beam. That is the world's truth, for
scoring only — a hand that picks from above and turns parts only about the vertical cannot
right them, so the recovery table counts those trials apart (`experiments.evaluation`).
"""

from __future__ import annotations

import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from contracts import se3
from contracts.errors import UsageError
from sim import robot
from sim.scene import TABLE_CENTRE_X, TABLE_HALF, body_name

FAULTS: tuple[str, ...] = ("slip", "push", "move", "bias", "skip")
BIAS_M = 0.015  # [m] the start-pose perception bias
PUSH_M = (0.020, 0.040)  # [m] how far a placed part is pushed
MOVE_M = (0.060, 0.120)  # [m] how far a person moves a part
_PENETRATION_M = 0.0005  # a displaced part may touch, not overlap, another [m]
SETTLE_S = 1.5  # [s] of sim time after a fault before its parts are judged at rest
TOPPLE_RAD = np.radians(30.0)  # a part whose up axis turned more than this (modulo its
# symmetries) rests on another face


def parse_faults(text: str | None) -> tuple[str, ...]:
    """`--faults NAME[,NAME]|all` → the names, checked (a usage error names the unknown one)."""
    if not text:
        return ()
    names = (
        FAULTS if text.strip() == "all" else tuple(n.strip() for n in text.split(",") if n.strip())
    )
    for n in names:
        if n not in FAULTS:
            raise UsageError(f"--faults: unknown fault {n!r}; known: {', '.join(FAULTS)}, all")
    if not names:
        raise UsageError(f"--faults needs a name: {', '.join(FAULTS)} or all")
    return tuple(dict.fromkeys(names))


def _rng(trial: str, what: str) -> np.random.Generator:
    return np.random.default_rng(zlib.crc32(f"{trial}/fault/{what}".encode()))


@dataclass
class Fault:
    """One trial's fault: its name, the transfer it comes at, and what it did."""

    name: str
    step: int  # the k-th transfer the robot carries out (0-based)
    trial: str
    record: dict[str, Any] = field(default_factory=dict)

    @property
    def happened(self) -> bool:
        return bool(self.record.get("happened"))

    def to_dict(self) -> dict[str, Any]:
        out = {"name": self.name, "step": self.step, **self.record}
        out.setdefault("happened", False)
        if not out["happened"]:
            out.setdefault("why", "the trial ended before the fault's moment")
        return out


def draw(names: Sequence[str], trial: str, plan_length: int) -> Fault | None:
    """The trial's fault: one of `names` and its moment, both from the trial's name."""
    if not names or plan_length < 1:
        return None
    rng = _rng(trial, "draw")
    name = names[int(rng.integers(len(names)))]
    return Fault(name=name, step=int(rng.integers(plan_length)), trial=trial)


def biased(fault: Fault | None, state: Mapping | None) -> Mapping | None:
    """The perceived start state with the bias fault applied (a copy), else `state` itself."""
    if fault is None or fault.name != "bias":
        return state
    if not isinstance(state, Mapping):
        fault.record = {"happened": False, "why": "no perceived start to bias (the oracle)"}
        return state
    records = [dict(r) for r in state.get("objects", []) if isinstance(r, Mapping)]
    if not records:
        return state
    rng = _rng(fault.trial, "bias")
    r = records[int(rng.integers(len(records)))]
    angle = float(rng.uniform(0.0, 2.0 * np.pi))
    shift = BIAS_M * np.array([np.cos(angle), np.sin(angle), 0.0])
    try:
        T = se3.as_matrix(r["pose"]).copy()
    except (KeyError, TypeError, ValueError):
        return state
    T[:3, 3] += shift
    r["pose"] = T
    fault.record = {
        "happened": True,
        "step": 0,
        "object": str(r.get("id")),
        "detail": f"start pose perceived {1000 * BIAS_M:.0f} mm off",
        "shift_m": shift.round(4).tolist(),
    }
    return {**state, "objects": records}


class Injector:
    """Carries out a trial's fault in the world, at its moment.

    Hooked into the executor (`Executor.on_phase`): it counts the transfers by their "grasp"
    phase, lets the hand go at the k-th "transfer" phase (slip), and displaces parts at the
    k-th "done" (push, move). `skips()` is asked before each transfer (skip)."""

    def __init__(self, fault: Fault | None, model: mujoco.MjModel, data: mujoco.MjData,
                 meshes: Mapping[str, Any]) -> None:  # fmt: skip
        self.fault = fault
        self.model, self.data = model, data
        self.meshes = {k: (v[0] if isinstance(v, tuple) else v) for k, v in meshes.items()}
        self.symmetries = {
            k: [np.asarray(S, float)[:3, :3] for S in v[1]] if isinstance(v, tuple) else []
            for k, v in meshes.items()
        }
        self.transfers = 0  # transfers begun (or skipped)
        self.grip_override: float | None = None
        self._upright: dict[str, np.ndarray] | None = None  # each part's rotation before

    # -- the executor's hook -------------------------------------------------------------------

    def on_phase(self, executor: Any, phase: str, oid: str) -> None:
        f = self.fault
        settled = f is not None and self.data.time >= f.record.get("sim_time", 0.0) + SETTLE_S
        if self._upright is not None and settled:
            self.settle()
        if phase == "grasp":
            self.transfers += 1
            executor.grip_override = None
        if f is None or f.happened or self.transfers - 1 != f.step:
            return
        if f.name == "slip" and phase == "transfer":
            executor.grip_override = robot.GRIPPER_OPEN
            f.record = {"happened": True, "object": oid, "sim_time": round(self.data.time, 3),
                        "detail": "the hand let the part go as the transfer began"}  # fmt: skip
            self._upright = self._rotations()  # the part in the hand as it was picked
        elif f.name == "push" and phase == "done":
            self._displace(oid, PUSH_M, turn=False, what="pushed")
        elif f.name == "move" and phase == "done":
            others = [o for o in self._free_parts() if o != oid]
            if others:
                rng = _rng(f.trial, "move-which")
                self._displace(others[int(rng.integers(len(others)))], MOVE_M, turn=True,
                               what="moved by a person", to_table=True)  # fmt: skip
            else:
                f.record = {"happened": False, "why": "no other part was free to move"}

    def skips(self) -> bool:
        """Whether the next transfer is the one the robot silently skips (counts it)."""
        f = self.fault
        if f is None or f.name != "skip" or f.happened or self.transfers != f.step:
            return False
        self.transfers += 1
        f.record = {"happened": True, "sim_time": round(self.data.time, 3),
                    "detail": "the robot skipped the transfer and reported it done"}  # fmt: skip
        return True

    def skipped_in_plan(self) -> None:
        """The open loop's skip: the step was taken out of the plan before it ran."""
        assert self.fault is not None and self.fault.name == "skip"
        self.fault.record = {"happened": True, "sim_time": 0.0,
                             "detail": "the robot skipped the transfer and reported it done"}  # fmt: skip

    def settle(self) -> None:
        """Judge, once, which parts the fault left resting on another face (`toppled` in the
        record): called `SETTLE_S` after the fault and when the trial ends."""
        f, before = self.fault, self._upright
        if f is None or before is None:
            return
        self._upright = None
        now = self._rotations()
        z = np.array([0.0, 0.0, 1.0])
        toppled = []
        for oid, R0 in before.items():
            ups = [R0 @ S @ z for S in self.symmetries.get(oid) or [np.eye(3)]]
            up_now = now[oid] @ z
            if min(np.arccos(np.clip(u @ up_now, -1.0, 1.0)) for u in ups) > TOPPLE_RAD:
                toppled.append(oid)
        f.record["toppled"] = toppled
        if toppled:
            f.record["detail"] = (
                f"{f.record.get('detail', '')}; left {', '.join(toppled)} on another face"
            )

    def _rotations(self) -> dict[str, np.ndarray]:
        out = {}
        for oid in self.meshes:
            body = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, body_name(oid))
            out[oid] = self.data.xmat[body].reshape(3, 3).copy()
        return out

    # -- displacing a part --------------------------------------------------------------------

    def _free_parts(self) -> list[str]:
        """Parts no other part rests on (by contact, the world's truth)."""
        bodies = {oid: mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, body_name(oid))
                  for oid in self.meshes}  # fmt: skip
        of_body = {b: oid for oid, b in bodies.items()}
        holding: set[str] = set()
        m, d = self.model, self.data
        for c in d.contact[: d.ncon]:
            b1, b2 = int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])
            if b1 in of_body and b2 in of_body:
                lower, upper = sorted((b1, b2), key=lambda b: d.xpos[b][2])
                if d.xpos[upper][2] > d.xpos[lower][2] + 1e-3:
                    holding.add(of_body[lower])
        return sorted(set(self.meshes) - holding)

    def _displace(self, oid: str, reach: tuple[float, float], *, turn: bool, what: str,
                  to_table: bool = False) -> None:  # fmt: skip
        f = self.fault
        assert f is not None
        m, d = self.model, self.data
        body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body_name(oid))
        adr = int(m.jnt_qposadr[m.body_jntadr[body]])
        dof = int(m.jnt_dofadr[m.body_jntadr[body]])
        q0 = d.qpos[adr : adr + 7].copy()
        before = self._rotations()
        rng = _rng(f.trial, what)
        vertices = np.asarray(self.meshes[oid].vertices)
        for _ in range(48):
            angle = float(rng.uniform(0.0, 2.0 * np.pi))
            dist = float(rng.uniform(*reach))
            q = q0.copy()
            q[:2] += dist * np.array([np.cos(angle), np.sin(angle)])
            if turn:
                yaw = float(rng.uniform(-np.pi / 2, np.pi / 2))
                qz = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
                out = np.zeros(4)
                mujoco.mju_mulQuat(out, qz, q[3:7])
                q[3:7] = out
            if not self._on_table(q[:2]):
                continue
            d.qpos[adr : adr + 7] = q
            if to_table:  # its lowest point on the table top (z = 0)
                R = np.zeros(9)
                mujoco.mju_quat2Mat(R, q[3:7])
                low = float(np.min((vertices @ R.reshape(3, 3).T)[:, 2]))
                d.qpos[adr + 2] = -low + 2e-4
            d.qvel[dof : dof + 6] = 0.0
            mujoco.mj_forward(m, d)
            if self._overlap_free(body):
                moved = d.qpos[adr : adr + 3] - q0[:3]
                f.record = {
                    "happened": True,
                    "object": oid,
                    "sim_time": round(d.time, 3),
                    "detail": f"{oid} {what} {1000 * float(np.linalg.norm(moved[:2])):.0f} mm",
                    "shift_m": moved.round(4).tolist(),
                }
                self._upright = before
                return
        d.qpos[adr : adr + 7] = q0
        mujoco.mj_forward(m, d)
        f.record = {"happened": False, "why": f"no free place to put {oid} ({what})"}

    @staticmethod
    def _on_table(xy: np.ndarray) -> bool:
        margin = 0.05
        return bool(
            abs(xy[0] - TABLE_CENTRE_X) < TABLE_HALF[0] - margin
            and abs(xy[1]) < TABLE_HALF[1] - margin
            and 0.25 < float(np.hypot(*xy)) < 0.75  # within the arm's reach, out of its base
        )

    def _overlap_free(self, body: int) -> bool:
        m, d = self.model, self.data
        for c in d.contact[: d.ncon]:
            b1, b2 = int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])
            if body in (b1, b2) and c.dist < -_PENETRATION_M:
                return False
        return True
