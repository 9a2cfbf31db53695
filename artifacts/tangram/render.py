# Written by people (the RIVET team), not by a model: the hand-written reference `render` for
# the tangram domain, the level a model's program should reach. It uses the toolbox renderer.
"""render(records, meshes, camera) -> {"rgb", "depth", "mask"}: what the camera sees of records.

The toolbox renderer takes the OpenCV camera as it is (x right, y down, z forward, K in
pixels) and returns metric depth along the optical axis (0 on the background) and the mask of
record indices (-1 on the background) from the same pass. Each piece gets its catalogue colour
(the two large and the two small triangles differ only in colour), so that a render can be
compared with camera images by eye.
"""

import numpy as np

from toolbox import render_scene

COLOURS = {  # catalogue colours, RGB 0–255
    "large_1": (217, 36, 36),
    "large_2": (36, 84, 217),
    "medium": (245, 204, 20),
    "small_1": (36, 163, 61),
    "small_2": (250, 128, 13),
    "square": (143, 61, 194),
    "parallelogram": (20, 194, 204),
}


def render(records, meshes, camera):
    colours = [COLOURS.get(str(r["id"]), (128, 128, 128)) for r in records]
    out = render_scene(list(records), meshes, camera, colors=colours)
    return {
        "rgb": np.asarray(out["rgb"], dtype=np.uint8),
        "depth": np.asarray(out["depth"], dtype=np.float32),
        "mask": np.asarray(out["mask"], dtype=np.int32),
    }
