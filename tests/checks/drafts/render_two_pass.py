# A correct `render` written the obvious pyrender way (a test draft, not a reference program):
# colour and depth from one ordinary pass, the mask from a second pass with pyrender's
# segmentation flag. The two passes rasterise the same triangles, but each resolves its own
# multisampled framebuffer, so along silhouettes a few pixels disagree — the mask shows an
# object where the colour pass's depth kept the background, and where two objects meet the
# averaged segmentation colours name a third. Nothing else is wrong with it: the checks must
# accept it (issue 16, item 8).
"""render(records, meshes, camera) -> {"rgb", "depth", "mask"}, with plain pyrender."""

import numpy as np
import pyrender

_RENDERERS = {}  # (width, height) -> pyrender.OffscreenRenderer
_MESHES = {}  # id of a trimesh -> (the trimesh, its pyrender mesh)
OPENCV_TO_OPENGL = np.diag([1.0, -1.0, -1.0, 1.0])


def _renderer(width, height):
    if (width, height) not in _RENDERERS:
        _RENDERERS[(width, height)] = pyrender.OffscreenRenderer(width, height)
    return _RENDERERS[(width, height)]


def _mesh(tm):
    if id(tm) not in _MESHES:
        _MESHES[id(tm)] = (tm, pyrender.Mesh.from_trimesh(tm, smooth=False))
    return _MESHES[id(tm)][1]


def render(records, meshes, camera):
    K = np.asarray(camera["K"], dtype=float)
    T_world_camera = np.asarray(camera["T_world_camera"], dtype=float)
    width, height = int(camera["width"]), int(camera["height"])
    scene = pyrender.Scene(bg_color=[0.0, 0.0, 0.0, 1.0], ambient_light=[0.35, 0.35, 0.35])
    seg = {}
    for index, record in enumerate(records):
        pose = np.asarray(record["pose"], dtype=float)
        node = scene.add(_mesh(meshes[record["mesh"]]), pose=pose)
        code = index + 1  # 0 stays the background
        seg[node] = (code & 255, (code >> 8) & 255, (code >> 16) & 255)
    # pyrender's camera looks down its -z with y up (OpenGL); the given camera is OpenCV's
    cam_pose = T_world_camera @ OPENCV_TO_OPENGL
    camera_node = pyrender.IntrinsicsCamera(
        fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2], znear=0.05, zfar=10.0
    )
    scene.add(camera_node, pose=cam_pose)
    scene.add(pyrender.DirectionalLight(intensity=3.0), pose=cam_pose)
    renderer = _renderer(width, height)
    colour, depth = renderer.render(scene)  # pass 1: colour and depth
    codes, _ = renderer.render(scene, flags=pyrender.RenderFlags.SEG, seg_node_map=seg)  # pass 2
    c = codes.astype(np.int32)
    mask = c[..., 0] + (c[..., 1] << 8) + (c[..., 2] << 16) - 1
    return {
        "rgb": np.ascontiguousarray(colour[..., :3], dtype=np.uint8),
        "depth": np.asarray(depth, dtype=np.float32),
        "mask": mask.astype(np.int32),
    }
