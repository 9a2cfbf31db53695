# A hostile `perceive` (a test draft): 4,000 schema-valid records — unique ids, a mesh of the
# domain, a proper pose — all stacked in one place. Every pairwise check on records (overlap,
# support, relations of what was perceived) would cost 4,000² contacts on the host; the checks
# must refuse the answer on its count, before any geometry (issue 35, item 4).
"""perceive(observation, meshes, camera) -> records: 4,000 of them, all in one place."""

import numpy as np

COUNT = 4000


def perceive(observation, meshes, camera):
    mesh = sorted(meshes)[0]
    pose = np.eye(4)
    pose[2, 3] = 0.05
    return [{"id": f"stacked_{i}", "mesh": mesh, "pose": pose} for i in range(COUNT)]
