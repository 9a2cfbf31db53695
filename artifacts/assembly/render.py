# Written by people (the RIVET team), not by a model: the hand-written reference `render` for
# the assembly domain, the level a model's program should reach. It uses the toolbox renderer.
"""render(records, meshes, camera) -> {"rgb", "depth", "mask"}: what the camera sees of records.

The toolbox renderer takes the OpenCV camera as it is (x right, y down, z forward, K in
pixels) and returns metric depth along the optical axis (0 on the background) and the mask of
record indices (-1 on the background) from the same pass, so mask and depth agree pixel for
pixel. Each part gets its catalogue colour so that renders compare with camera images by eye.
"""

import numpy as np

from toolbox import render_scene

COLOURS = {  # catalogue colours, RGB 0–255
    "pillar_1": (204, 46, 36),
    "pillar_2": (247, 143, 26),
    "beam": (38, 87, 217),
    "arch": (242, 209, 31),
    "roof": (38, 153, 61),
    "cylinder": (143, 66, 194),
    "lblock": (26, 189, 204),
    "block": (245, 117, 168),
}


def render(records, meshes, camera):
    colours = [COLOURS.get(str(r["id"]), (128, 128, 128)) for r in records]
    out = render_scene(list(records), meshes, camera, colors=colours)
    return {
        "rgb": np.asarray(out["rgb"], dtype=np.uint8),
        "depth": np.asarray(out["depth"], dtype=np.float32),
        "mask": np.asarray(out["mask"], dtype=np.int32),
    }
