# A realistic failing draft, kept to show what the checks reject (not a reference program).
# perceive v1 follows the toolbox recipe for a flat piece word for word: the outline of each
# colour's mask, mapped onto the plane of the top faces, fitted with `fit_polygon_pose`. But a
# tangram piece is not a flat polygon to the camera: the mask holds the piece's visible side
# faces (below the top plane, so they map outwards, towards the camera) and its 20 mm knob
# (above it, so it maps away from the camera and, on the small triangles, past their edges).
# The outline is biased by millimetres towards the camera and the orientation of small pieces
# by degrees; see what `rivet check tangram perceive domains/tangram/programs/drafts/perceive_v1.py`
# says. The reference separates top face, knob and sides by their depth first. It thins each
# outline to some 60 points, which keeps its CPU time (about 0.35 s a call) far from the 1 s
# online budget: its check report is then the same on a fast machine and on a loaded one.
"""perceive(observation, meshes, camera) -> records: colour mask outline → polygon pose."""

import numpy as np

from toolbox import (
    fit_polygon_pose,
    mask_contour,
    pixels_to_plane,
    pose_from_xyz_yaw,
    segment_hue,
)

HUES = {  # catalogue hue [deg] of each piece's colour
    "large_1": 0.0,
    "large_2": 223.0,
    "medium": 49.0,
    "small_1": 131.0,
    "small_2": 29.0,
    "square": 279.0,
    "parallelogram": 184.0,
}
MESHES = {
    "large_1": "large_triangle",
    "large_2": "large_triangle",
    "medium": "medium_triangle",
    "small_1": "small_triangle",
    "small_2": "small_triangle",
    "square": "square",
    "parallelogram": "parallelogram",
}
TOP = 0.015  # [m]


def perceive(observation, meshes, camera):
    rgb = np.asarray(observation["rgb"], dtype=np.uint8)
    records = []
    for oid, hue in HUES.items():
        key = MESHES[oid]
        mask = segment_hue(rgb, hue - 10.0, hue + 10.0, sat_min=0.35)
        if mask.sum() < 50:
            continue
        outline = pixels_to_plane(mask_contour(mask), camera, (0.0, 0.0, 1.0, -TOP))[:, :2]
        outline = outline[:: max(1, len(outline) // 60)]  # some 60 points: fast enough
        v = np.asarray(meshes[key].vertices, dtype=float)
        template = v[v[:, 2] < 1e-6][:, :2]
        order = np.argsort(np.arctan2(template[:, 1], template[:, 0]))
        fit = fit_polygon_pose(template[order], outline)
        records.append(
            {"id": oid, "mesh": key, "pose": pose_from_xyz_yaw(fit.x, fit.y, 0.0, fit.angle)}
        )
    return records
