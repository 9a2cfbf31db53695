# Written by people (the RIVET team), not by a model: the hand-written reference `render` for
# the cubes domain, the level a model's program should reach. It uses the toolbox renderer.
"""render(records, meshes, camera) -> {"rgb", "depth", "mask"}: what the camera sees of records.

The toolbox renderer takes the OpenCV camera as it is (x right, y down, z forward, K in
pixels) and returns metric depth along the optical axis (0 on the background) and the mask of
record indices (-1 on the background) from the same pass. Each cube gets its catalogue colour
so that the render can be compared with camera images by eye.
"""

import numpy as np

from toolbox import render_scene

COLOURS = {  # catalogue colours, RGB 0–255
    "red": (209, 26, 26),
    "green": (31, 158, 46),
    "blue": (26, 71, 217),
    "yellow": (242, 209, 20),
    "purple": (133, 46, 184),
    "cyan": (26, 199, 217),
}


def render(records, meshes, camera):
    colours = [COLOURS.get(str(r["id"]), (128, 128, 128)) for r in records]
    out = render_scene(list(records), meshes, camera, colors=colours)
    return {
        "rgb": np.asarray(out["rgb"], dtype=np.uint8),
        "depth": np.asarray(out["depth"], dtype=np.float32),
        "mask": np.asarray(out["mask"], dtype=np.int32),
    }
