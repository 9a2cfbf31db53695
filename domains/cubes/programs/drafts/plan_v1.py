# A realistic failing draft, kept to show what the checks reject (not a reference program).
# plan v1 forgets temporary placements: it builds the goal bottom-up, but when a cube's goal
# spot is occupied, or the cube it needs is buried under a wrong-order stack, it just moves the
# cube there anyway. `rivet check cubes plan domains/cubes/programs/drafts/plan_v1.py` fails
# `property.reaches_goal` with the collision (or the pick from under a stack) it causes.
"""plan(start_state, goal_state, meshes) -> plan: bottom-up, one move per cube."""

import numpy as np

SIDE = 0.04


def plan(start_state, goal_state, meshes):
    start = {r["id"]: np.asarray(r["pose"], float) for r in start_state["objects"]}
    goal = {r["id"]: np.asarray(r["pose"], float) for r in goal_state["objects"]}
    if sorted(start) != sorted(goal):
        return {"status": "infeasible", "reason": "start and goal hold different cubes"}
    for i, T in goal.items():
        if T[2, 3] > SIDE / 2 + 0.004 and not any(
            j != i
            and abs(T[2, 3] - U[2, 3] - SIDE) < 0.008
            and np.linalg.norm(T[:2, 3] - U[:2, 3]) < SIDE
            for j, U in goal.items()
        ):
            return {"status": "infeasible", "reason": f"'{i}' floats in the goal"}
    steps = []
    for i in sorted(goal, key=lambda k: (goal[k][2, 3], k)):  # lowest goal first
        if np.linalg.norm(start[i][:3, 3] - goal[i][:3, 3]) > 0.004:
            steps.append({"object": i, "target_pose": goal[i].tolist()})
    return {"status": "ok", "steps": steps}
