"""RGB-D observations of scenes, their sensor model, and the BOP-style folder format.

Rendering uses MuJoCo's offscreen OpenGL (set `MUJOCO_GL=egl` on headless machines). A
camera is the DESIGN dict (OpenCV axes, K with square pixels and a centred principal point);
the image is rendered through a movable MuJoCo camera placed at that pose.

Depth sensor model (`DepthNoise`, on by default), after a ZED 2i stereo camera at 720p:
- metric depth along the optical axis, from the renderer's z-buffer;
- Gaussian noise with σ(z) = 0.6 mm + 1.2 mm·(z / 1 m)², i.e. ≈1 mm at 0.6 m, ≈1.6 mm at
  0.9 m: stereo error grows with the square of the distance;
- quantised to 1 mm;
- missing pixels (depth 0): at depth discontinuities (a 3×3 neighbourhood spanning more than
  10 mm), dropped with probability 0.7, where stereo matching fails; 0.2 % random speckle
  dropouts; everything nearer than 0.3 m or farther than 6 m.
The noise is seeded, so an observation is reproducible.

The folder format (rgb.png, depth.png, camera.json) is `artifacts.observations`: the thin
runtime reads it without this module's simulator.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import mujoco
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from contracts import to_jsonable, validate
from contracts.errors import ContractError
from domains import Domain
from sim.errors import InvalidCameraError, SimError
from sim.scene import RENDER_CAMERA, camera_quat, fovy_of, object_of_geom, scene_model


@dataclass(frozen=True, kw_only=True)
class DepthNoise:
    """Stereo depth sensor model (see the module docstring); all lengths in metres."""

    sigma_base: float = 0.0006  # [m]
    sigma_quadratic: float = 0.0012  # [m] at 1 m, grows with z²
    quantum: float = 0.001  # [m]
    edge_jump: float = 0.01  # depth span in a 3×3 neighbourhood that marks an edge [m]
    edge_dropout: float = 0.7  # probability an edge pixel is missing
    speckle_dropout: float = 0.002  # probability any other pixel is missing
    min_range: float = 0.3  # [m]
    max_range: float = 6.0  # [m]

    def sigma(self, z: np.ndarray) -> np.ndarray:
        """Standard deviation [m] of the depth noise at depth `z` [m]."""
        return self.sigma_base + self.sigma_quadratic * np.square(z)


DEFAULT_NOISE = DepthNoise()


def apply_depth_noise(
    depth: np.ndarray, rng: np.random.Generator, model: DepthNoise = DEFAULT_NOISE
) -> np.ndarray:
    """Noisy float32 depth [m] from a clean one (0 = invalid stays invalid)."""
    z = depth.astype(np.float32)
    valid = (z >= model.min_range) & (z <= model.max_range)
    noisy = z + rng.standard_normal(z.shape, dtype=np.float32) * model.sigma(z).astype(np.float32)
    noisy = np.round(noisy / model.quantum) * model.quantum
    kernel = np.ones((3, 3), np.uint8)
    span = cv2.dilate(z, kernel) - cv2.erode(z, kernel)
    edge = span > model.edge_jump
    u = rng.random(z.shape, dtype=np.float32)
    drop = (edge & (u < model.edge_dropout)) | (~edge & (u < model.speckle_dropout))
    return np.where(valid & ~drop, noisy, 0.0).astype(np.float32)


# -- rendering ------------------------------------------------------------------------------


def check_camera(camera: Mapping) -> dict:
    """A camera dict with arrays, refused when MuJoCo cannot render it exactly."""
    try:
        validate("camera", to_jsonable(dict(camera)))
    except ContractError as e:
        raise ContractError(f"camera.{e.path}".rstrip("."), e.problem) from None
    k = np.asarray(camera["K"], float)
    w, h = int(camera["width"]), int(camera["height"])
    if abs(k[0, 0] - k[1, 1]) > 1e-6 * k[0, 0] or k[0, 1] != 0:
        raise InvalidCameraError("camera: K must have square pixels (fx == fy, no skew)")
    if abs(k[0, 2] - (w - 1) / 2) > 0.5 or abs(k[1, 2] - (h - 1) / 2) > 0.5:
        raise InvalidCameraError(
            "camera: the principal point must be the image centre ((w-1)/2, (h-1)/2)"
        )
    return {
        "width": w,
        "height": h,
        "K": k,
        "T_world_camera": np.asarray(camera["T_world_camera"], float),
    }


class Renderer:
    """Offscreen renderer for one compiled model: RGB, clean depth and object masks."""

    def __init__(self, model: mujoco.MjModel, width: int, height: int) -> None:
        if width > model.vis.global_.offwidth or height > model.vis.global_.offheight:
            raise InvalidCameraError(
                f"camera: {width}×{height} exceeds the offscreen buffer "
                f"{model.vis.global_.offwidth}×{model.vis.global_.offheight}"
            )
        self.model = model
        try:
            self._gl = mujoco.Renderer(model, height=height, width=width)
        except Exception as e:  # the GL backend reports many kinds of errors
            raise SimError(
                f"cannot open an offscreen OpenGL context ({e}); on a headless machine set "
                "MUJOCO_GL=egl and PYOPENGL_PLATFORM=egl"
            ) from e
        self._cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, RENDER_CAMERA)
        if self._cam < 0:
            raise SimError(
                f"model has no camera {RENDER_CAMERA!r}: build it with sim.scene.build_spec"
            )
        self._option = mujoco.MjvOption()
        geom_object = object_of_geom(model)
        self._geom_object = geom_object

    def close(self) -> None:
        self._gl.close()

    def render(
        self,
        data: mujoco.MjData,
        camera: Mapping,
        *,
        depth: bool = True,
        mask: bool = False,
        mask_ids: Sequence[str] | None = None,
    ) -> dict[str, np.ndarray]:
        """Render `data` from `camera`: {"rgb", "depth" (clean) [, "mask"]}.

        Args:
            mask_ids: object ids giving the mask's indices (mask = index, -1 background).
        """
        cam = check_camera(camera)
        self.model.cam_pos[self._cam] = cam["T_world_camera"][:3, 3]
        self.model.cam_quat[self._cam] = camera_quat(cam["T_world_camera"])
        self.model.cam_fovy[self._cam] = fovy_of(cam)
        mujoco.mj_camlight(self.model, data)
        gl = self._gl
        gl.update_scene(data, camera=self._cam, scene_option=self._option)
        out = {"rgb": gl.render().copy()}
        if depth:
            gl.enable_depth_rendering()
            gl.update_scene(data, camera=self._cam, scene_option=self._option)
            z = gl.render().astype(np.float32)
            gl.disable_depth_rendering()
            z[z >= 0.99 * self.model.vis.map.zfar * self.model.stat.extent] = 0.0
            out["depth"] = z
        if mask:
            gl.enable_segmentation_rendering()
            gl.update_scene(data, camera=self._cam, scene_option=self._option)
            seg = gl.render()
            gl.disable_segmentation_rendering()
            index = {i: k for k, i in enumerate(mask_ids or [])}
            lut = np.full(self.model.ngeom + 1, -1, np.int32)
            for g, oid in self._geom_object.items():
                lut[g] = index.get(oid, -1)
            ids = seg[..., 0]
            is_geom = seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)
            out["mask"] = np.where(
                is_geom & (ids >= 0), lut[np.clip(ids, 0, self.model.ngeom)], -1
            ).astype(np.int32)
        return out


_RENDERERS: OrderedDict[tuple, Renderer] = OrderedDict()


def renderer_for(model: mujoco.MjModel, width: int, height: int) -> Renderer:
    """A cached renderer for (model, size); the least recently used beyond 4 are closed."""
    key = (id(model), width, height)
    if key in _RENDERERS:
        _RENDERERS.move_to_end(key)
        return _RENDERERS[key]
    r = Renderer(model, width, height)
    _RENDERERS[key] = r
    while len(_RENDERERS) > 4:
        _, old = _RENDERERS.popitem(last=False)
        old.close()
    return r


def observe(
    domain: Domain,
    scene: Mapping,
    camera: str | Mapping = "front",
    *,
    noise: DepthNoise | None = DEFAULT_NOISE,
    seed: int = 0,
    mask: bool = False,
) -> dict[str, Any]:
    """An observation of a parsed scene (objects only, no robot).

    Args:
        camera: a camera name of the domain (front, view1, view2) or a camera dict.
        noise: the depth sensor model; None gives the clean rendered depth.
        seed: seeds the depth noise.
        mask: also return "mask": (H, W) int32, index of the visible object in
            ``scene["objects"]``, -1 for background.
    Returns:
        {"rgb": (H, W, 3) uint8, "depth": (H, W) float32 [m], "camera": camera dict[, "mask"]}
    """
    cam = domain.camera(camera) if isinstance(camera, str) else check_camera(camera)
    sm = scene_model(domain, scene)
    r = renderer_for(sm.model, cam["width"], cam["height"])
    ids = [o["id"] for o in scene["objects"]]
    images = r.render(sm.data, cam, mask=mask, mask_ids=ids)
    if noise is not None:
        images["depth"] = apply_depth_noise(images["depth"], np.random.default_rng(seed), noise)
    return {**images, "camera": cam}


# -- contact sheets -------------------------------------------------------------------------


def contact_sheet(
    domain: Domain,
    scenes: Sequence[tuple[str, Mapping]],
    *,
    cameras: Sequence[str] = ("front", "view1", "view2"),
    tile_width: int = 640,
    title: str = "",
) -> np.ndarray:
    """An RGB image: one row per (label, scene), one column per camera."""
    tiles = []
    for label, scene in scenes:
        row = []
        for c in cameras:
            rgb = observe(domain, scene, c, noise=None)["rgb"]
            h = round(rgb.shape[0] * tile_width / rgb.shape[1])
            img = Image.fromarray(rgb).resize((tile_width, h), Image.Resampling.LANCZOS)
            ImageDraw.Draw(img).text(
                (10, 8), f"{label} · {c}", fill=(255, 255, 255), font=_font(22)
            )
            row.append(np.asarray(img))
        tiles.append(np.concatenate(row, axis=1))
    sheet = np.concatenate(tiles, axis=0)
    if title:
        band = Image.new("RGB", (sheet.shape[1], 44), (24, 24, 24))
        ImageDraw.Draw(band).text((12, 8), title, fill=(240, 240, 240), font=_font(26))
        sheet = np.concatenate([np.asarray(band), sheet], axis=0)
    return sheet


def _font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow without FreeType sizes
        return ImageFont.load_default()


__all__ = [
    "DEFAULT_NOISE",
    "DepthNoise",
    "Renderer",
    "apply_depth_noise",
    "check_camera",
    "contact_sheet",
    "observe",
    "renderer_for",
]
