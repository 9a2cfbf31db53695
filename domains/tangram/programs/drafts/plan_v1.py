# A realistic failing draft, kept to show what the checks reject (not a reference program).
# plan v1 treats tangram as "put every piece at its goal": it moves the pieces in catalogue
# order straight to their perceived goal poses (the symmetric equivalent nearest in yaw). It
# forgets that a start piece may lie where another piece's goal is, or that pieces may have to
# swap places, so nothing is ever moved aside first; and it places the goal poses as
# perceived, 0.5 mm apart, where a millimetre of perception error makes neighbours overlap.
# `rivet check tangram plan domains/tangram/programs/drafts/plan_v1.py` fails
# `property.reaches_goal` with the collision this causes.
"""plan(start_state, goal_state, meshes) -> plan: one move per piece, in catalogue order."""

import numpy as np

ORDER = ["large_1", "large_2", "medium", "small_1", "small_2", "square", "parallelogram"]
SYMMETRY = {"square": 4, "parallelogram": 2}


def _yaw(T):
    return float(np.arctan2(T[1, 0], T[0, 0]))


def plan(start_state, goal_state, meshes):
    start = {r["id"]: np.asarray(r["pose"], float) for r in start_state["objects"]}
    goal = {r["id"]: (r["mesh"], np.asarray(r["pose"], float)) for r in goal_state["objects"]}
    if sorted(start) != sorted(goal):
        return {"status": "infeasible", "reason": "start and goal hold different pieces"}
    for i, (_, T) in goal.items():
        if abs(T[2, 3]) > 0.005:
            return {"status": "infeasible", "reason": f"'{i}' is not on the table in the goal"}
    steps = []
    for i in sorted(goal, key=lambda k: (ORDER.index(k) if k in ORDER else len(ORDER), k)):
        mesh, T = goal[i]
        S = start[i]
        period = 2 * np.pi / SYMMETRY.get(mesh, 1)
        d = (_yaw(T) - _yaw(S) + period / 2) % period - period / 2
        if np.linalg.norm(T[:2, 3] - S[:2, 3]) <= 0.002 and abs(d) <= np.radians(2):
            continue
        yaw = _yaw(S) + d
        P = np.eye(4)
        P[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
        P[:2, 3] = T[:2, 3]
        steps.append({"object": i, "target_pose": P.tolist()})
    return {"status": "ok", "steps": steps}
