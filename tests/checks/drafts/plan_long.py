# A hostile `plan` (a test draft): 40,000 steps, each putting the first object back where it
# is — forty times the plan contract's cap of 1,000. Handed to the simulated robot it would run
# for hours; listed in an error message it is megabytes. The checks and the trial runner must
# refuse it on its count, before any geometry or execution (issue 35, item 4).
"""plan(start_state, goal_state, meshes) -> plan: 40,000 steps that change nothing."""

COUNT = 40_000


def plan(start_state, goal_state, meshes):
    first = start_state["objects"][0]
    step = {"object": first["id"], "target_pose": first["pose"]}
    return {"status": "ok", "steps": [step] * COUNT}
