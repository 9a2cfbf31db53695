"""What a failing plan step looks like, for the feedback: the state drawn, and which part of the
gripper hits what.

Design rule: feedback only, never a verdict. The verdicts are `geometry.apply_plan` and the
robot's `MoveCheck` (`checks.robot`); this module redraws the state they judged and, for a
step without a grasp, shows the grasp the hand model would take if the neighbours were not
there (`geometry.plan_grasps` with no obstacles), with the gripper's boxes
(`geometry.FingerModel`, the same volumes the model tests) at the pick and at the place, and
names each box that enters a neighbour.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from checks import images
from checks.context import SuiteContext
from contracts import se3
from geometry import (
    ROBOT,
    STROKE,
    TOLERANCES,
    Body,
    FingerModel,
    Piece,
    body_separation,
    plan_grasps,
)

_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


def state_before(start: Sequence[Mapping[str, Any]], steps: Sequence[Mapping], k: int) -> list:
    """The records after steps 0 … k − 1 (the state step `k` picks from)."""
    state = {str(r["id"]): dict(r, pose=np.asarray(r["pose"], float)) for r in start}
    for step in steps[:k]:
        oid = str(step["object"])
        if oid in state:
            state[oid] = dict(state[oid], pose=se3.as_matrix(step["target_pose"]))
    return list(state.values())


def _objects(ctx: SuiteContext, records: Sequence[Mapping], roles: Mapping[str, str]) -> list:
    return [
        {
            "id": b.id,
            "pieces": [p.vertices for p in b.pieces],
            "role": roles.get(b.id, "other"),
        }
        for b in ctx.spec.geometry.bodies(list(records))
    ]


def _part_names(fingers: FingerModel) -> list[str]:
    """Names of `FingerModel.boxes(...)`, in its order."""
    names = []
    for i in range(len(fingers.segments) + 1):
        what = (
            "fingertip"
            if i == 0
            else "finger linkage"
            if i == len(fingers.segments)
            else "upper finger"
        )
        names += [what, what]
    names.append("spring links between the fingers")
    palm = ["gripper base", f"{ROBOT.arm.name} wrist"]
    names += [palm[j] if j < len(palm) else "arm" for j in range(len(fingers.palm))]
    return names


def _side(direction: np.ndarray) -> str:
    d = np.asarray(direction, float)[:2]
    if np.linalg.norm(d) < 1e-4:
        return ""
    axis = int(np.argmax(np.abs(d)))
    return (
        ("on the +x side (away from the robot)", "on the -x side (towards the robot)"),
        ("on the +y side (the robot's left)", "on the -y side (the robot's right)"),
    )[axis][0 if d[axis] > 0 else 1]


def gripper_hits(
    ctx: SuiteContext,
    mesh: str,
    T_from: np.ndarray,
    T_to: np.ndarray,
    pick_others: Sequence[Mapping],
    place_others: Sequence[Mapping],
) -> tuple[str, list[dict], list[dict]]:
    """The grasp the hand would take with no neighbours, and its parts that enter one.

    Returns (a sentence, boxes at the pick, boxes at the place); boxes are
    {"corners": (8, 3), "hit": bool} for `images.state_views`.
    """
    fingers = ROBOT.gripper.fingers
    report = plan_grasps(
        ctx.spec.meshes[mesh],
        T_from,
        T_to,
        symmetries=list(ctx.spec.symmetries.get(mesh, [np.eye(4)])),
        limit=None,
    )
    if not report.grasps:
        return (
            f"even with no other object around, the hand finds no grasp ({report.summary()})",
            [],
            [],
        )
    g = report.grasps[0]
    tip = max(STROKE.tip_at_gap(g.width), STROKE.tip_at_gap(g.open_gap))
    margin = min(TOLERANCES.grasp_margins)
    names = _part_names(fingers)
    found: list[str] = []
    drawn: dict[str, list[dict]] = {}
    for where, tcp, others in (
        ("pick", g.pick_tcp, pick_others),
        ("place", g.place_tcp, place_others),
    ):
        R, t = tcp[:3, :3], tcp[:3, 3]
        bodies = ctx.spec.geometry.bodies(list(others))
        boxes = []
        for k, (centre, half) in enumerate(fingers.boxes(g.open_gap, tip, margin)):
            corners = (centre + _SIGNS * half) @ R.T + t
            hit_by = []
            box = Body(id="", pieces=(Piece.of(corners),))
            for b in bodies:
                d, _ = body_separation(box, b, cutoff=0.0)
                if d < 0:
                    hit_by.append((b.id, -d))
            if hit_by:
                name = names[k] if k < len(names) else "gripper"
                side = _side(R @ centre) if k < len(names) - len(fingers.palm) - 1 else ""
                whom = ", ".join(f"'{i}' (by {1000 * depth:.1f} mm)" for i, depth in hit_by)
                found.append(f"at the {where} the {name} {side} enters {whom}".replace("  ", " "))
            boxes.append({"corners": corners, "hit": bool(hit_by)})
        drawn[where] = boxes
    grasp = (
        f"the grasp the hand would take with no neighbours closes across faces "
        f"{1000 * g.width:.0f} mm apart, the jaws opened to {1000 * g.open_gap:.0f} mm"
    )
    if not found:
        text = (
            f"{grasp}; it clears the neighbours by {1000 * margin:g} mm (another grasp was tried)"
        )
    else:
        text = f"{grasp}, with the gripper kept {1000 * margin:g} mm from everything: " + "; ".join(
            found[:4]
        )
    return text, drawn["pick"], drawn["place"]


def step_picture(
    ctx: SuiteContext,
    start: Sequence[Mapping[str, Any]],
    steps: Sequence[Mapping[str, Any]],
    k: int,
    *,
    blockers: Sequence[str] = (),
    goal: Sequence[Mapping[str, Any]] | None = None,
    hands: bool = False,
    name: str,
    what: str,
) -> tuple[str, list[dict[str, str]]]:
    """The state at step `k` (before it, and after it) as an image under the check run's
    folder; with `hands`, the gripper of the grasp the hand would take, and a sentence naming
    which of its parts hits what ("" without `hands`).

    `k` = len(steps): the final state (with `goal`, the goal places of objects not there).
    """
    out_dir = ctx.out_dir
    final = k >= len(steps)
    before = state_before(start, steps, min(k, len(steps)))
    after = before if final else state_before(start, steps, k + 1)
    moved = None if final else str(steps[k]["object"])
    roles = {b: "blocker" for b in blockers}
    if moved is not None:
        roles[moved] = "moved"
    text = ""
    pick_boxes: list[dict] = []
    place_boxes: list[dict] = []
    if hands and moved is not None:
        me = next(r for r in before if str(r["id"]) == moved)
        others_b = [r for r in before if str(r["id"]) != moved]
        others_a = [r for r in after if str(r["id"]) != moved]
        text, pick_boxes, place_boxes = gripper_hits(
            ctx, str(me["mesh"]), me["pose"], se3.as_matrix(steps[k]["target_pose"]), others_b,
            others_a,
        )  # fmt: skip
    if out_dir is None:
        return text, []
    ghosts = []
    if goal is not None:
        wrong = set(blockers)
        ghosts = [
            dict(o, role="goal") for o in _objects(ctx, [g for g in goal if g["id"] in wrong], {})
        ]
    rows = []
    if final:
        rows.append(
            images.state_views(
                _objects(ctx, after, roles) + ghosts,
                title="the last state (green outlines: goal places not reached)",
            )
        )
    else:
        everything = [*_objects(ctx, before, roles), *_objects(ctx, after, roles)]
        lo = np.min([np.asarray(p).min(0) for o in everything for p in o["pieces"]], axis=0)
        hi = np.max([np.asarray(p).max(0) for o in everything for p in o["pieces"]], axis=0)
        for b in [*pick_boxes, *place_boxes]:
            c = np.asarray(b["corners"])
            near = np.all(np.abs(c[:, :2].mean(0) - (lo[:2] + hi[:2]) / 2) < 0.4)
            if near:
                lo, hi = np.minimum(lo, c.min(0)), np.maximum(hi, c.max(0))
        hi[2] = min(hi[2], max(lo[2], 0.0) + 0.3)
        bounds = (lo - 0.02, hi + 0.02)
        rows.append(
            images.state_views(
                _objects(ctx, before, roles), boxes=pick_boxes, bounds=bounds,
                title=f"step {k}, at the pick: '{moved}' where it is",
            )
        )  # fmt: skip
        rows.append(
            images.state_views(
                _objects(ctx, after, roles), boxes=place_boxes, bounds=bounds,
                title=f"step {k}, at the place: '{moved}' at its target",
            )
        )  # fmt: skip
    caption = (
        f"{what}: the state at step {k}" + ("" if final else " before and after it")
        + ", from above (x up, y to the left) and from behind the robot; blue: the object "
        "moved (outlined when others hide it), red: the objects in the way"
        + (", orange: gripper parts that enter another object (outlined: the rest of the "
           "gripper)" if pick_boxes else "")
    )  # fmt: skip
    return text, images.write_png(out_dir, name, images.stack_rows(rows), caption)
