"""RGB-D observations of scenes, their sensor model, camera files, and contact sheets.

Rendering uses MuJoCo's offscreen OpenGL (set `MUJOCO_GL=egl` on headless machines). A
camera is the DESIGN dict (OpenCV axes, K with square pixels and a centred principal point);
the image is rendered through a movable MuJoCo camera placed at that pose.

API (docs/observations.md has the details and the values):

    observe(domain, scene, camera="front", *, seed=0, realism=None, calibration_seed=None,
            noise=<the level's depth model>, mask=False) -> observation
    observe_with_truth(...same arguments...) -> (observation, truth)
    load_camera(path) -> camera dict          # a camera file; bad ones raise UsageErrors
    parse_camera(value, where=...) -> camera dict

- `camera`: a view name of the domain (front, view1, view2), a camera dict, or a camera
  file path (`load_camera`).
- `realism`: "clean" (None, the default), "default", "harsh" or a `sim.realism.Realism`.
  "clean" is the protocol before realism existed, bit for bit.
- the observation ``{"rgb", "depth", "camera"[, "mask"]}`` is what `perceive` gets: its
  "camera" is the CALIBRATED camera (off by the level's calibration error), while the
  image was rendered from the TRUE camera. ``truth`` (host-only: never give it to a policy)
  is ``{"camera": true camera, "realism": level name, "exposure", "white_balance",
  "calibration_error": (metres, radians)}``.
- `calibration_seed` (default `seed`) draws the calibration error: one camera has one
  calibration, so give a trial's start and goal the same calibration seed.
- `noise`, when passed, replaces the level's depth model (None: the clean rendered depth);
  ``observe(domain, scene, camera, noise=None, mask=True)`` is the clean view the checks use.

Depth sensor model (`DepthNoise`, on by default), after a ZED 2i stereo camera at 720p:
- metric depth along the optical axis, from the renderer's z-buffer;
- Gaussian noise with σ(z) = 0.6 mm + 1.2 mm·(z / 1 m)², i.e. ≈1 mm at 0.6 m, ≈1.6 mm at
  0.9 m: stereo error grows with the square of the distance;
- quantised to 1 mm;
- missing pixels (depth 0): at depth discontinuities (a 3×3 neighbourhood spanning more than
  10 mm), dropped with probability 0.7, where stereo matching fails; 0.2 % random speckle
  dropouts; everything nearer than 0.3 m or farther than 6 m.
The noise is seeded, so an observation is reproducible. The RGB sensor, lights and
calibration models are `sim.realism`'s.

The folder format (rgb.png, depth.png, camera.json) is `artifacts.observations`: the thin
runtime reads it without this module's simulator.
"""

from __future__ import annotations

import json
import math
import os
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from contracts import to_jsonable, validate
from contracts.errors import ContractError, UsageError
from domains import Domain
from domains.catalogue import CameraSpec
from sim.errors import InvalidCameraError, SimError
from sim.realism import (
    DEFAULT_NOISE,
    DepthNoise,
    Realism,
    apply_depth_noise,
    calibrated_camera,
    calibration_error,
    draw_gains,
    sensor_rgb,
    streams,
    vary_lighting,
)
from sim.realism import realism as realism_level
from sim.scene import (
    OFFSCREEN,
    RENDER_CAMERA,
    Lighting,
    _pose,
    camera_quat,
    fovy_of,
    lighting_of,
    object_of_geom,
    scene_model,
    set_lighting,
)

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
        # The context's framebuffers sized to this renderer's images, not to the largest the
        # model allows: the same pixels, and a multisampled 1920×1080 buffer holds about
        # 65 MB more of a CPU rasteriser's memory than a 1280×720 one.
        g = model.vis.global_
        saved = (g.offwidth, g.offheight)
        g.offwidth, g.offheight = width, height
        try:
            self._gl = mujoco.Renderer(model, height=height, width=width)
        except Exception as e:  # the GL backend reports many kinds of errors
            raise SimError(
                f"cannot open an offscreen OpenGL context ({e}); on a headless machine set "
                "MUJOCO_GL=egl and PYOPENGL_PLATFORM=egl"
            ) from e
        finally:
            g.offwidth, g.offheight = saved
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
        lighting: Lighting | None = None,
        quick: bool = False,
    ) -> dict[str, np.ndarray]:
        """Render `data` from `camera`: {"rgb", "depth" (clean) [, "mask"]}.

        Args:
            mask_ids: object ids giving the mask's indices (mask = index, -1 background).
            lighting: lights for this render only (`sim.scene.Lighting`); the model's own
                lights are restored afterwards. None: the model's lights as they are.
            quick: no shadows and no reflections (a video frame: about 5× faster on a CPU
                rasteriser); never for an observation.
        """
        kw = {"depth": depth, "mask": mask, "mask_ids": mask_ids, "quick": quick}
        if lighting is None:
            return self._render(data, camera, **kw)  # type: ignore[arg-type]
        saved = lighting_of(self.model)
        set_lighting(self.model, data, lighting)
        try:
            return self._render(data, camera, **kw)  # type: ignore[arg-type]
        finally:
            set_lighting(self.model, data, saved)

    def _render(
        self,
        data: mujoco.MjData,
        camera: Mapping,
        *,
        depth: bool,
        mask: bool,
        mask_ids: Sequence[str] | None,
        quick: bool = False,
    ) -> dict[str, np.ndarray]:
        cam = check_camera(camera)
        self.model.cam_pos[self._cam] = cam["T_world_camera"][:3, 3]
        self.model.cam_quat[self._cam] = camera_quat(cam["T_world_camera"])
        self.model.cam_fovy[self._cam] = fovy_of(cam)
        mujoco.mj_camlight(self.model, data)
        gl = self._gl
        gl.update_scene(data, camera=self._cam, scene_option=self._option)
        gl.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = not quick
        gl.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = not quick
        out = {"rgb": gl.render().copy()}
        seg = None
        if depth:
            gl.enable_depth_rendering()
            gl.update_scene(data, camera=self._cam, scene_option=self._option)
            z = gl.render().astype(np.float32)
            gl.disable_depth_rendering()
            if mask:  # the same pass drew the segment ids: a depth render sets their flags
                seg = _segments_drawn(gl)
            z[z >= 0.99 * self.model.vis.map.zfar * self.model.stat.extent] = 0.0
            out["depth"] = z
        if mask:
            if seg is None:
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


def _segments_drawn(gl: mujoco.Renderer) -> np.ndarray:
    """(H, W, 2) (object id, object type) of each pixel, -1 for none, read from the colour
    buffer of the pass `gl` drew last — one drawn with `mjRND_SEGMENT` and `mjRND_IDCOLOR`, as
    a depth or a segmentation render is: the segmentation render's output for that pass
    (`tests/sim/test_observation.py` holds them equal), without drawing it again."""
    h, w = gl.height, gl.width
    rgb = np.empty((h, w, 3), np.uint8)
    # mujoco.Renderer keeps its context and viewport private (tests/sim/test_observation.py)
    mujoco.mjr_readPixels(rgb, None, gl._rect, gl._mjr_context)
    if gl._gl_context:  # EGL and OSMesa draw bottom-up
        rgb = np.flipud(rgb)
    rgb32 = rgb.astype(np.uint32)
    segid = rgb32[..., 0] + (rgb32[..., 1] << 8) + (rgb32[..., 2] << 16)  # 0: background
    scene = gl.scene
    lut = np.full((scene.ngeom + 1, 2), -1, np.int32)
    for g in scene.geoms[: scene.ngeom]:
        if g.segid != -1:
            lut[g.segid + 1] = (g.objid, g.objtype)
    return lut[segid]


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


def release_renderers() -> None:
    """Close every cached renderer (each holds a GL context: 30-40 MB on a CPU rasteriser)."""
    while _RENDERERS:
        _, r = _RENDERERS.popitem()
        r.close()


_DEPTH_OF_LEVEL: Any = object()  # `noise` not passed: the realism level's depth model


def observe_with_truth(
    domain: Domain,
    scene: Mapping,
    camera: str | Mapping | os.PathLike = "front",
    *,
    seed: int = 0,
    realism: str | Realism | None = None,
    calibration_seed: int | None = None,
    noise: DepthNoise | None = _DEPTH_OF_LEVEL,
    mask: bool = False,
    clean: bool = False,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """An observation of a parsed scene (objects only, no robot) and its host-only truth.

    Args:
        camera: a view name of the domain (front, view1, view2), a camera dict, or the path
            of a camera file (`load_camera`). This is the TRUE camera: the image comes from it.
        seed: seeds every random effect (depth noise exactly as before realism existed).
        realism: "clean" (None), "default", "harsh" or a `sim.realism.Realism`.
        calibration_seed: seeds the calibration error (default `seed`).
        noise: replaces the level's depth model when passed; None gives the clean depth.
        mask: also return "mask": (H, W) int32, index of the visible object in
            ``scene["objects"]``, -1 for background (from the true camera, like the image).
        clean: also put the clean render (rgb, depth before the sensor's effects) in the
            truth as "clean_rgb", "clean_depth" (the image checks' reference, one render).
    Returns:
        (observation, truth): observation ``{"rgb": (H, W, 3) uint8, "depth": (H, W) float32
        [m], "camera": the CALIBRATED camera dict[, "mask"]}``, what `perceive` gets;
        truth ``{"camera": the true camera, "realism": level name, "exposure": gain,
        "white_balance": (3,) gains, "calibration_error": (metres, radians)}``, never for a
        policy.
    """
    level = realism_level(realism)
    depth_model = level.depth if noise is _DEPTH_OF_LEVEL else noise
    if isinstance(camera, str) and camera in domain.cameras:
        cam = domain.camera(camera)
    elif isinstance(camera, os.PathLike) or (
        isinstance(camera, str) and (camera.endswith(".json") or Path(camera).is_file())
    ):
        cam = load_camera(camera)
    elif isinstance(camera, str):
        cam = domain.camera(camera)  # refused, naming the known views
    else:
        cam = check_camera(camera)
    rng = streams(seed, calibration_seed)
    sm = scene_model(domain, scene)
    r = renderer_for(sm.model, cam["width"], cam["height"])
    ids = [o["id"] for o in scene["objects"]]
    lighting = (
        vary_lighting(lighting_of(sm.model), rng["lights"], level) if level.varies_lights else None
    )
    images = r.render(sm.data, cam, mask=mask, mask_ids=ids, lighting=lighting)
    exposure, white_balance = draw_gains(rng["gains"], level)
    rendered = {"clean_rgb": images["rgb"], "clean_depth": images["depth"]} if clean else {}
    if level.varies_rgb:
        images["rgb"] = sensor_rgb(
            images["rgb"], rng["pixels"], level, exposure=exposure, white_balance=white_balance
        )
    else:
        exposure, white_balance = 1.0, np.ones(3)
    if depth_model is not None:
        images["depth"] = apply_depth_noise(images["depth"], rng["depth"], depth_model)
    calibrated = calibrated_camera(cam, rng["calibration"], level)
    truth = {
        "camera": cam,
        "realism": level.name,
        "exposure": float(exposure),
        "white_balance": np.asarray(white_balance, float),
        "calibration_error": calibration_error(calibrated, cam),
        **rendered,
    }
    return {**images, "camera": calibrated}, truth


def observe(
    domain: Domain,
    scene: Mapping,
    camera: str | Mapping | os.PathLike = "front",
    *,
    seed: int = 0,
    realism: str | Realism | None = None,
    calibration_seed: int | None = None,
    noise: DepthNoise | None = _DEPTH_OF_LEVEL,
    mask: bool = False,
) -> dict[str, Any]:
    """The observation `perceive` gets: ``observe_with_truth(...)[0]`` (same arguments).

    Its "camera" is the calibrated camera; with the default ``realism=None`` ("clean") that
    is the true camera and everything is as before realism existed:
    ``observe(d, s, c, seed=k)`` has the stereo depth noise, ``noise=None`` the clean depth.
    """
    obs, _ = observe_with_truth(
        domain,
        scene,
        camera,
        seed=seed,
        realism=realism,
        calibration_seed=calibration_seed,
        noise=noise,
        mask=mask,
    )
    return obs


# -- camera files ---------------------------------------------------------------------------


class CameraFileError(InvalidCameraError):
    """A camera file that cannot be used (exit code 2); the message names the file."""


_VIEW_KEYS = {"width", "height", "fovy", "position", "target"}
_CAMERA_KEYS = {"width", "height", "K", "T_world_camera"}


def _number(value: Any, path: str, *, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ContractError(path, f"must be a finite number, got {value!r}")
    if not low < value < high:
        raise ContractError(path, f"must be in ({low:g}, {high:g}), got {value!r}")
    return float(value)


def _point(value: Any, path: str) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise ContractError(path, "must be a list of 3 numbers [m]")
    return tuple(  # type: ignore[return-value]
        _number(v, f"{path}[{i}]", low=-100, high=100) for i, v in enumerate(value)
    )


def _size(value: Any, path: str, limit: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 2:
        raise ContractError(path, f"must be an integer ≥ 2, got {value!r}")
    if value > limit:
        raise InvalidCameraError(f"camera.{path}: {value} exceeds the renderer's {limit} px")
    return value


def parse_camera(value: Any, *, where: str = "camera") -> dict:
    """A camera dict from JSON: the DESIGN form ``{width, height, K, T_world_camera}`` (an
    observation folder's camera.json, with its depth_scale, too) or a domain's cameras.json
    entry ``{width, height, fovy [deg], position [m], target [m]}`` (OpenCV axes, x right,
    image up towards +z).

    Raises:
        ContractError: malformed (names the field).
        InvalidCameraError: a camera the MuJoCo renderer cannot reproduce (non-square pixels,
            skew, a principal point off the image centre, bigger than the offscreen buffer, a
            pose that is not a rigid motion, a view looking straight up or down).
    """
    if not isinstance(value, Mapping):
        raise ContractError("", f"{where}: a camera must be a JSON object")
    keys = set(value)
    if "K" in keys or "T_world_camera" in keys:
        body = {k: v for k, v in value.items() if k != "depth_scale"}
        missing = _CAMERA_KEYS - set(body)
        if missing:
            raise ContractError("", f"a camera needs {', '.join(sorted(missing))}")
        cam = check_camera(body)
        _size(cam["width"], "width", OFFSCREEN[0])
        _size(cam["height"], "height", OFFSCREEN[1])
        cam["T_world_camera"] = _pose(value["T_world_camera"], "camera.T_world_camera")
        if abs(np.linalg.det(cam["K"])) < 1e-9 or cam["K"][0, 0] <= 0:
            raise InvalidCameraError("camera.K: the focal length must be positive")
        if not np.allclose(cam["K"][2], (0, 0, 1)):
            raise InvalidCameraError("camera.K: the last row must be [0, 0, 1]")
        return cam
    if keys >= _VIEW_KEYS:
        extra = keys - _VIEW_KEYS - {"name"}
        if extra:
            raise ContractError(sorted(extra)[0], "unknown field of a camera view")
        w = _size(value["width"], "width", OFFSCREEN[0])
        h = _size(value["height"], "height", OFFSCREEN[1])
        fovy = _number(value["fovy"], "fovy", low=0, high=180)
        pos, target = _point(value["position"], "position"), _point(value["target"], "target")
        forward = np.subtract(target, pos)
        dist = np.linalg.norm(forward)
        if dist < 1e-6:
            raise InvalidCameraError("camera: position and target coincide")
        if np.linalg.norm(np.cross(forward / dist, (0, 0, 1))) < 1e-3:
            raise InvalidCameraError(
                "camera: a view looking straight up or down has no defined image axes; "
                "give the DESIGN form with T_world_camera"
            )
        spec = CameraSpec(name="file", width=w, height=h, fovy=fovy, position=pos, target=target)
        return check_camera(spec.to_camera())
    raise ContractError(
        "",
        "a camera file holds {width, height, K, T_world_camera} (the DESIGN camera) or "
        "{width, height, fovy, position, target} (a cameras.json view)",
    )


def load_camera(path: str | os.PathLike) -> dict:
    """The camera dict in a camera file (the forms of `parse_camera`).

    Raises:
        CameraFileError (a UsageError: exit code 2): no such file, not JSON, or any problem of
            `parse_camera`; the message names the file and the problem.
    """
    p = Path(path)
    if not p.is_file():
        raise CameraFileError(f"{path}: no such camera file")
    try:
        value = json.loads(p.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise CameraFileError(f"{p}: not JSON ({getattr(e, 'msg', e)})") from None
    try:
        return parse_camera(value, where=str(p))
    except (UsageError, ContractError) as e:
        raise CameraFileError(f"{p}: {e}") from None


# -- contact sheets -------------------------------------------------------------------------


CameraEntry = str | os.PathLike | Mapping | tuple[str, "str | os.PathLike | Mapping"]


def _camera_entry(entry: CameraEntry) -> tuple[str, str | os.PathLike | Mapping]:
    """(label, camera) of a contact sheet column."""
    if isinstance(entry, tuple):
        return entry[0], entry[1]
    if isinstance(entry, os.PathLike) or (isinstance(entry, str) and entry.endswith(".json")):
        return Path(entry).stem, Path(entry)
    if isinstance(entry, str):
        return entry, entry
    return "camera", entry


def contact_sheet(
    domain: Domain,
    scenes: Sequence[tuple[str, Mapping]],
    *,
    cameras: Sequence[CameraEntry] = ("front", "view1", "view2"),
    tile_width: int = 640,
    title: str = "",
    realism: str | Realism | Sequence[str | Realism] | None = None,
    seed: int = 0,
    crop: tuple[int, int, int, int] | None = None,
) -> np.ndarray:
    """An RGB image: one row per (label, scene) and realism level, one column per camera.

    Args:
        cameras: view names, camera file paths, camera dicts, or (label, any of these).
        realism: a level (None: clean) or a list of levels, each giving its own rows.
        seed: the observations' seed (the same for every tile, so levels compare).
        crop: (x, y, width, height) of the full-size image to show in each tile, e.g. a
            `tile_width`-wide crop to see the sensor noise 1:1.
    """
    levels: list[str | Realism | None] = (
        list(realism) if isinstance(realism, list | tuple) else [realism]  # type: ignore[list-item]
    )
    columns = [_camera_entry(c) for c in cameras]
    tiles = []
    for label, scene in scenes:
        for level in levels:
            row = []
            for name, c in columns:
                rgb = observe(domain, scene, c, noise=None, realism=level, seed=seed)["rgb"]
                if crop is not None:
                    x, y, w, h = crop
                    rgb = np.ascontiguousarray(rgb[y : y + h, x : x + w])
                h = round(rgb.shape[0] * tile_width / rgb.shape[1])
                img = Image.fromarray(rgb)
                if img.width != tile_width:
                    img = img.resize((tile_width, h), Image.Resampling.LANCZOS)
                text = (
                    f"{label} · {name}"
                    if level is None
                    else (f"{label} · {realism_level(level).name} · {name}")
                )
                ImageDraw.Draw(img).text((10, 8), text, fill=(255, 255, 255), font=_font(22))
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
    "CameraFileError",
    "DepthNoise",
    "Realism",
    "Renderer",
    "apply_depth_noise",
    "check_camera",
    "contact_sheet",
    "load_camera",
    "observe",
    "observe_with_truth",
    "parse_camera",
    "release_renderers",
    "renderer_for",
]
