"""Planning one transfer's motion: the grasp, the transfer height, and every segment from the
approach to the retreat, kinematically (IK tick by tick) before the physics runs any of it.

Design rule: it plans on the executor's belief only — the object's believed pose, the other
objects at their believed poses as obstacles — and on the arm's own state (its commanded
joints). An unreachable waypoint is found here, before the arm moves.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

from contracts import se3
from geometry.grasps import Grasp, Obstacle, plan_grasps
from geometry.robot import STROKE
from sim import robot
from sim._motion import PlanFailure, PlannedSegment, Segment, plan_segments
from sim.execution import ExecutorConfig
from sim.ik import ArmIK
from sim.reach import Reach

# The labels of a transfer's segments that the executor cuts its phases at (`split_at`).
CLOSING = "closing"
LIFTING = "lifting"
TRANSFERRING = "transferring"
DESCENDING = "descending to the target"
REACHING = "reaching the target"
SETTLING = "settling before release"
RETREATING = "retreating"


class TransferAbort(Exception):
    """A transfer cannot be planned: (kind, phase, reason), as `StepFailure` has them."""

    def __init__(self, kind: str, phase: str, reason: str, grasp: Grasp | None = None):
        super().__init__(reason)
        self.kind, self.phase, self.reason, self.grasp = kind, phase, reason, grasp


@dataclass(frozen=True, kw_only=True)
class Chosen:
    """The grasp of a transfer and its planned pick (up to the lift)."""

    grasp: Grasp
    pick: list[PlannedSegment]
    transfer_z: float  # TCP height of the transfer [m]
    long_way: bool  # the transfer turns the wrist the long way round
    transfer_q: np.ndarray | None = None  # (7,) the transfer is a joint move to these joints


class TransferPlanner:
    """Plans transfers for one robot (`ik`, its wrist range) with one configuration."""

    def __init__(
        self, ik: ArmIK, config: ExecutorConfig, wrist: tuple[float, float], tick_dt: float
    ) -> None:
        self.ik, self.config, self.wrist, self.tick_dt = ik, config, wrist, tick_dt
        self.reach = Reach(ik)

    # -- the grasp ---------------------------------------------------------------------------

    def choose(
        self,
        q_cmd: np.ndarray,
        grip_cmd: float,
        mesh: trimesh.Trimesh,
        symmetries: Sequence[np.ndarray],
        T_pick: np.ndarray,
        target: np.ndarray,
        others: Sequence[Obstacle],
    ) -> Chosen:
        """The best grasp whose whole motion has IK solutions, with its pick planned.

        Per grasp, best first: Cartesian moves all along; the transfer turning the wrist the
        long way round; then the move above the object in joint space (`_through_joint_space`),
        with either transfer. Only when no grasp has any of these, the grasps again, best
        first, with the transfer in joint space (`_joint_transfer`)."""
        report = plan_grasps(
            mesh,
            T_pick,
            target,
            symmetries=list(symmetries),
            pick_obstacles=others,
            place_obstacles=others,
        )
        if not report.grasps:
            raise TransferAbort(
                "no_grasp", "grasp", f"no feasible top-down grasp: {report.summary()}"
            )
        tops = [float(_world_vertices(o.mesh, o.pose)[:, 2].max()) for o in others]
        candidates, unreachable = self._rank_by_wrist(report.grasps)
        if not candidates:
            raise TransferAbort("unreachable", "grasp", unreachable)
        c = self.config
        first_failure: PlanFailure | None = None
        for grasp in candidates[: c.max_grasp_candidates]:
            transfer_z = self._transfer_height(mesh, grasp, T_pick, tops)
            segments = self.pick_segments(q_cmd, grip_cmd, grasp, transfer_z)
            # the long way round only helps for a turn of more than a quarter
            ways = (False, True) if abs(grasp.transfer_yaw) > np.pi / 2 else (False,)
            places = {w: self.place_motion(grasp, grasp.place_tcp, transfer_z, w) for w in ways}
            for long_way in ways:
                planned = plan_segments(self.ik, q_cmd, segments + places[long_way], self.tick_dt)
                if not isinstance(planned, PlanFailure):
                    return Chosen(
                        grasp=grasp,
                        pick=planned[: len(segments)],
                        transfer_z=transfer_z,
                        long_way=long_way,
                    )
                first_failure = first_failure or planned
            for long_way in ways:
                alternative = self._through_joint_space(q_cmd, segments, places[long_way])
                if alternative is not None:
                    return Chosen(
                        grasp=grasp,
                        pick=alternative[: len(segments)],
                        transfer_z=transfer_z,
                        long_way=long_way,
                    )
        for grasp in candidates[: c.max_grasp_candidates]:
            transfer_z = self._transfer_height(mesh, grasp, T_pick, tops)
            segments = self.pick_segments(q_cmd, grip_cmd, grasp, transfer_z)
            cartesian = plan_segments(self.ik, q_cmd, segments, self.tick_dt)
            pick = (
                self._through_joint_space(q_cmd, segments, [])
                if isinstance(cartesian, PlanFailure)
                else cartesian
            )
            if pick is None:
                continue
            floor = max([*tops, 0.0]) + c.clearance / 2
            held = np.vstack([np.asarray(mesh.vertices), _fingertips(grasp)])
            q_goal = self._joint_transfer(pick[-1].q[-1], grasp, held, floor, transfer_z)
            if q_goal is not None:
                return Chosen(
                    grasp=grasp,
                    pick=pick,
                    transfer_z=transfer_z,
                    long_way=False,
                    transfer_q=q_goal,
                )
        assert first_failure is not None
        raise TransferAbort(
            "unreachable",
            "grasp",
            f"{first_failure.describe()} (best of "
            f"{min(len(candidates), c.max_grasp_candidates)} grasps)",
        )

    def _rank_by_wrist(self, grasps: Sequence[Grasp]) -> tuple[list[Grasp], str]:
        """Drop grasps whose pick or place pose has no IK solution (`sim.reach`, the test the
        plan checks use too); among equally good ones prefer the wrist angle farthest from its
        limits (the 2F-85's half-turn symmetry gives two wrist angles per grasp)."""
        ranked, reason = [], ""
        for g in grasps[: 2 * self.config.max_grasp_candidates]:
            reached = self.reach.grasp(g, wrist=self.wrist)
            if reached.ok:
                ranked.append((round(g.score, 3), reached.wrist_margin, g))
            else:
                reason = reason or reached.reason
        ranked.sort(key=lambda r: (-r[0], -r[1]))
        return [r[2] for r in ranked], reason

    def _transfer_height(
        self, mesh: trimesh.Trimesh, grasp: Grasp, T_pick: np.ndarray, tops: Sequence[float]
    ) -> float:
        c = self.config
        bottom = float(_world_vertices(mesh, T_pick)[:, 2].min())
        hang = max(grasp.pick_tcp[2, 3] - bottom, STROKE.tip_at_gap(grasp.width))
        z = max([*tops, 0.0]) + hang + c.clearance
        return max(
            z, c.min_transfer_height, grasp.pick_tcp[2, 3] + 0.05, grasp.place_tcp[2, 3] + 0.05
        )

    def _through_joint_space(
        self, q_cmd: np.ndarray, segments: list[Segment], place: list[Segment]
    ) -> list[PlannedSegment] | None:
        """The pick and place again, but with the move above the object made in joint space to
        a fresh IK solution, for when the Cartesian move from the current arm configuration
        runs a joint into its limit (typically the wrist, which the transfer then has to turn
        further) or the descent from it does. Seeds turn the wrist a quarter or a half turn
        either way from READY; the joint move must keep the TCP within 2 cm of the transfer
        height. None when no seed gives a plan."""
        k = next(i for i, seg in enumerate(segments) if seg.label == "moving above the object")
        before = plan_segments(self.ik, q_cmd, segments[:k], self.tick_dt)
        if isinstance(before, PlanFailure):
            return None
        q_from = before[-1].q[-1] if before else q_cmd
        above = segments[k].goal
        assert above is not None
        z_low = min(self.ik.fk(q_from)[2, 3], above[2, 3]) - 0.02

        def high(tcps: np.ndarray) -> bool:  # the move must not dip towards the objects
            return bool(tcps[:, 2, 3].min() >= z_low)

        for joint_move in self._joint_moves(q_from, segments[k], high):
            planned = plan_segments(
                self.ik,
                q_cmd,
                [*segments[:k], joint_move, *segments[k + 1 :], *place],
                self.tick_dt,
            )
            if not isinstance(planned, PlanFailure):
                return planned
        return None

    def _joint_transfer(
        self, q_from: np.ndarray, grasp: Grasp, held: np.ndarray, floor: float, z: float
    ) -> np.ndarray | None:
        """The joints of a transfer made in joint space from the end of the lift (`q_from`) to
        a fresh IK solution above the target, from which the rest of the place plans: for when
        every Cartesian transfer ends where the descent cannot go on (typically with the wrist
        at its limit, where the descent needs it to turn further). Seeds as
        `_through_joint_space`; all along the move every point of `held` (the object's vertices
        and the fingertips, in the object's frame) must stay above `floor` [m] (half the
        clearance over the believed objects' tops: the move may swing and tilt the hand). None
        when no seed gives a plan."""
        motion = self.place_motion(grasp, grasp.place_tcp, z)
        T_tcp_object = se3.inverse(grasp.T_object_tcp)
        points = np.c_[held, np.ones(len(held))] @ T_tcp_object.T  # (n, 4) in the TCP frame

        def clear(tcps: np.ndarray) -> bool:
            return bool((tcps[:, 2, :] @ points.T).min() >= floor)

        for joint_move in self._joint_moves(q_from, motion[0], clear):
            planned = plan_segments(self.ik, q_from, [joint_move, *motion[1:]], self.tick_dt)
            if not isinstance(planned, PlanFailure):
                return joint_move.q_goal
        return None

    def _joint_moves(
        self, q_from: np.ndarray, move: Segment, ok: Callable[[np.ndarray], bool]
    ) -> Iterator[Segment]:
        """`move` (a Cartesian segment) as joint moves from `q_from` to fresh IK solutions of
        its goal, seeded with READY turned towards it and the wrist a quarter or a half turn
        either way; only those whose TCP poses along the way (n, 4, 4) are `ok`."""
        goal = move.goal
        assert goal is not None
        lo, hi = self.wrist
        for turn in (0.0, -np.pi / 2, np.pi / 2, -np.pi, np.pi):
            seed = robot.READY_QPOS.copy()
            seed[0] = np.arctan2(goal[1, 3], goal[0, 3])
            seed[6] = np.clip(seed[6] + turn, lo + 0.1, hi - 0.1)
            sol = self.ik.solve(goal, seed)
            if not sol.ok:
                continue
            far = float(np.max(np.abs(sol.q - q_from)))
            n = max(2, int(np.ceil(far / 0.02)))
            path = q_from + np.linspace(0.0, 1.0, n)[:, None] * (sol.q - q_from)
            if ok(np.array([self.ik.fk(q) for q in path])):
                yield self._joint_segment(q_from, sol.q, move)

    def _joint_segment(self, q_from: np.ndarray, q_goal: np.ndarray, move: Segment) -> Segment:
        """`move` made as a joint move from `q_from` to `q_goal` at the joint speed."""
        c = self.config
        far = float(np.max(np.abs(q_goal - q_from)))
        return Segment(
            label=move.label,
            q_goal=q_goal,
            duration=max(c.min_move_time, far / c.joint_speed),
            grip=move.grip,
        )

    # -- segments ----------------------------------------------------------------------------

    def pick_segments(
        self, q_cmd: np.ndarray, grip_cmd: float, grasp: Grasp, z: float
    ) -> list[Segment]:
        """Approach (rise, move above, descend, reach), then close, squeeze, lift (labelled
        `CLOSING`, then `LIFTING`)."""
        c = self.config
        open_ctrl = STROKE.ctrl_for_gap(grasp.open_gap)
        T_now = self.ik.fk(q_cmd)
        above = grasp.pick_tcp.copy()
        above[2, 3] = z
        near = grasp.pick_tcp.copy()
        near[2, 3] += c.final_approach
        segs = []
        if z - T_now[2, 3] > 0.001:
            up = T_now.copy()
            up[2, 3] = z
            segs.append(
                Segment(
                    label="rising to the transfer height",
                    goal=up,
                    duration=self.duration(T_now, up, c.approach_speed),
                )
            )
            T_now = up
        segs += [
            Segment(
                label="moving above the object",
                goal=above,
                duration=self.duration(T_now, above, c.move_speed),
            ),
            Segment(
                label="descending onto the object",
                goal=near,
                duration=self.duration(above, near, c.approach_speed),
            ),
        ]
        segs[0] = Segment(
            label=segs[0].label,
            goal=segs[0].goal,
            duration=segs[0].duration,
            grip=(grip_cmd, open_ctrl),
        )
        return [
            *segs,
            Segment(
                label="reaching the grasp",
                goal=grasp.pick_tcp,
                duration=max(c.final_approach / c.final_speed, 0.2),
            ),
            Segment(label=CLOSING, duration=c.close_time, grip=(open_ctrl, robot.GRIPPER_CLOSED)),
            Segment(label="squeezing", duration=c.grip_settle),
            Segment(
                label=LIFTING,
                goal=above,
                duration=self.duration(grasp.pick_tcp, above, c.approach_speed),
            ),
        ]

    def place_motion(
        self, grasp: Grasp, place_tcp: np.ndarray, z: float, long_way: bool = False
    ) -> list[Segment]:
        """transfer, descend, final descent, pause, open, pause, retreat; the transfer turns the
        wrist the long way round with `long_way`."""
        c = self.config
        open_ctrl = STROKE.ctrl_for_gap(grasp.open_gap)
        release = place_tcp.copy()
        release[2, 3] += c.release_height
        above = release.copy()
        above[2, 3] = z
        near = release.copy()
        near[2, 3] += c.final_approach
        lifted = grasp.pick_tcp.copy()
        lifted[2, 3] = z
        # The transfer turns about the vertical, by the short yaw or the long way round. Both
        # are explicit turns: the geodesic of a half turn has no preferred side (nor, with a
        # small tilt left over, a vertical axis), so it may take the long way's side and
        # swing the wrist into the limit the long way avoids.
        R = above[:3, :3] @ lifted[:3, :3].T
        turn = float(np.arctan2(R[1, 0], R[0, 0]))
        if long_way:
            turn -= np.copysign(2 * np.pi, turn)
        return [
            Segment(
                label=TRANSFERRING,
                goal=above,
                duration=max(self.duration(lifted, above, c.move_speed), abs(turn) / c.turn_speed),
                turn=turn,
            ),
            Segment(
                label=DESCENDING,
                goal=near,
                duration=self.duration(above, near, c.approach_speed),
            ),
            Segment(
                label=REACHING,
                goal=release,
                duration=max(c.final_approach / c.final_speed, 0.2),
            ),
            Segment(label=SETTLING, duration=c.release_settle),
            Segment(label="opening", duration=c.open_time, grip=(robot.GRIPPER_CLOSED, open_ctrl)),
            Segment(label="settling after release", duration=c.release_settle),
            Segment(
                label=RETREATING,
                goal=above,
                duration=self.duration(release, above, c.approach_speed),
            ),
        ]

    def place_segments(
        self,
        q_cmd: np.ndarray,
        grasp: Grasp,
        T_place: np.ndarray,
        z: float,
        *,
        in_hand: np.ndarray | None = None,
        start: str | None = None,
        long_way: bool = False,
        transfer_q: np.ndarray | None = None,
    ) -> list[PlannedSegment]:
        """Plan the place from the arm's command `q_cmd`, corrected for the object's pose in the
        hand when there is an estimate of it (`in_hand`: T_tcp_object): from after the lift, or
        from the segment labelled `start` (`DESCENDING`: from above the target; `REACHING`:
        from the end of the descent, `final_approach` above the release). `T_place` is the target with the grasp's symmetry applied; the
        transfer turns the long way round with `long_way`, or is a joint move to `transfer_q`
        (as `choose` chose)."""
        candidates = []
        if in_hand is not None and self.config.in_hand_correction:
            corrected = T_place @ se3.inverse(in_hand)
            tilt = np.arccos(np.clip(-corrected[2, 2], -1.0, 1.0))
            if tilt < np.radians(10.0):
                candidates.append(corrected)
        candidates.append(grasp.place_tcp)
        failure: PlanFailure | None = None
        for place_tcp in candidates:
            motion = self.place_motion(grasp, place_tcp, z, long_way)
            if transfer_q is not None and start is None:
                motion[0] = self._joint_segment(q_cmd, transfer_q, motion[0])
            first = 0 if start is None else [m.label for m in motion].index(start)
            planned = plan_segments(self.ik, q_cmd, motion[first:], self.tick_dt)
            if not isinstance(planned, PlanFailure):
                return planned
            failure = failure or planned
        assert failure is not None
        raise TransferAbort("unreachable", "transfer", failure.describe(), grasp)

    def duration(self, T0: np.ndarray, T1: np.ndarray, speed: float) -> float:
        c = self.config
        dist = float(np.linalg.norm(T1[:3, 3] - T0[:3, 3]))
        angle = se3.rotation_angle(T0[:3, :3].T @ T1[:3, :3])
        return max(c.min_move_time, dist / speed, angle / c.turn_speed)


def _fingertips(grasp: Grasp) -> np.ndarray:
    """The two fingertips (2, 3) at the grasp's width, in the held object's frame."""
    depth = STROKE.tip_at_gap(grasp.width)
    tips = np.array([[0.0, -grasp.width / 2, depth, 1.0], [0.0, grasp.width / 2, depth, 1.0]])
    return (tips @ grasp.T_object_tcp.T)[:, :3]


def _world_vertices(mesh: trimesh.Trimesh, T: np.ndarray) -> np.ndarray:
    return np.asarray(mesh.vertices) @ T[:3, :3].T + T[:3, 3]


def obstacles(
    belief: Mapping[str, np.ndarray], meshes: Mapping[str, trimesh.Trimesh], skip: str
) -> list[Obstacle]:
    """The believed objects other than `skip`, as obstacles for the grasp planner."""
    return [
        Obstacle(id=o, mesh=meshes[o], pose=T)
        for o, T in belief.items()
        if o != skip and o in meshes
    ]
