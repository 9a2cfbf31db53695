"""Offscreen rendering of object records with the OpenCV camera, and render comparison.

Design rule: one call renders exactly what the generated `render` function must return —
`{"rgb", "depth", "mask"}` — from records, meshes and a camera dict (pixel centres at
integer coordinates). Mask and depth come from one pass without anti-aliasing, so they agree
pixel for pixel. The first call takes ~0.5–1 s (the OpenGL context, the meshes uploaded); later
calls ~0.05–0.15 s at 1280×720, whatever their image size.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import os
import threading
from collections import OrderedDict
from collections.abc import Mapping, Sequence

import numpy as np

from toolbox._common import camera_matrices, camera_size
from toolbox.errors import RendererUnavailableError, ToolboxError

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
# Mesa would otherwise write a shader cache under $HOME, which the sandbox forbids (and which
# saves nothing measurable for pyrender's few shaders).
os.environ.setdefault("MESA_SHADER_CACHE_DISABLE", "true")

__all__ = ["compare_renders", "overlay_mask", "render_scene"]

# One pyrender context for every image size (a size change only re-makes its framebuffer:
# drawn cameras come in many sizes), with the meshes uploaded to it (a pyrender mesh's GPU
# buffers belong to one context). Calls are serialised by a lock, and each gives the calling
# thread's previous EGL context back (MuJoCo's, say) so that renderers can share a thread.
_MAX_MESHES = 256  # uploaded (mesh, colour) pairs kept
_LOCK = threading.Lock()
_CONTEXTS: list[_Context] = []  # the one context, once made
_OPENCV_TO_OPENGL = np.diag([1.0, -1.0, -1.0, 1.0])


def render_scene(
    records: Sequence[Mapping],
    meshes: Mapping[str, object],
    camera: dict,
    *,
    colors: Sequence | Mapping | None = None,
    background: Sequence[int] = (0, 0, 0),
    ambient: float = 0.35,
    light_intensity: float = 3.0,
    znear: float = 0.05,
    zfar: float = 10.0,
) -> dict[str, np.ndarray]:
    """Render object records as seen by the camera.

    Args:
        records: list of `{"id", "mesh", "pose"}`; `pose` is `T_world_object` (4, 4) [m].
        meshes: `{mesh key: trimesh.Trimesh}` in the objects' canonical frames [m].
        camera: `{"width", "height", "K" (3, 3), "T_world_camera" (4, 4)}`, OpenCV convention.
        colors: RGB 0–255 per record: a list aligned with `records`, or a dict keyed by record
            id or mesh key. None (or a missing key) uses the mesh's own colours/texture.
        background: RGB 0–255 of empty pixels.
        ambient: ambient light level in [0, 1]; a directional light shines along the
            optical axis with `light_intensity`.
        znear, zfar: clipping distances [m]; geometry outside them is not drawn.

    Returns:
        {"rgb": (H, W, 3) uint8, "depth": (H, W) float32 [m] along the optical axis, 0 on
        background, "mask": (H, W) int32 index into `records` of the visible object, -1 on
        background}.

    Raises:
        ToolboxError: a record has an unknown mesh key or a bad pose, or bad camera/colours.
        RendererUnavailableError: no OpenGL context (install Mesa EGL or set
            PYOPENGL_PLATFORM=osmesa).
    """
    import pyrender

    K, T_wc = camera_matrices(camera)
    width, height = camera_size(camera)
    if not 0 < znear < zfar:
        raise ToolboxError(f"need 0 < znear < zfar, got znear={znear}, zfar={zfar}")
    items = [_resolve(i, r, meshes, colors) for i, r in enumerate(records)]
    with _LOCK, _current_context_restored():
        ctx = _context(width, height)
        scene = pyrender.Scene(
            bg_color=[*(np.asarray(background, float) / 255.0), 1.0],
            ambient_light=[ambient] * 3,
        )
        seg = {}
        for index, (mesh, color, pose) in enumerate(items):
            node = scene.add(ctx.mesh(mesh, color), pose=pose)
            code = index + 1  # 0 is background
            seg[node] = (code & 255, (code >> 8) & 255, (code >> 16) & 255)
        cam_pose = T_wc @ _OPENCV_TO_OPENGL
        scene.add(_OpenCVCamera(K, znear=znear, zfar=zfar), pose=cam_pose)
        if light_intensity > 0:
            scene.add(pyrender.DirectionalLight(intensity=light_intensity), pose=cam_pose)
        flags = pyrender.RenderFlags.SKIP_CULL_FACES
        rgb, _ = ctx.renderer.render(scene, flags=flags)
        codes, depth = ctx.renderer.render(
            scene, flags=flags | pyrender.RenderFlags.SEG, seg_node_map=seg
        )
    c = codes.astype(np.int32)
    mask = c[..., 0] + (c[..., 1] << 8) + (c[..., 2] << 16) - 1
    depth = np.where(mask >= 0, depth, 0.0).astype(np.float32)
    return {"rgb": np.ascontiguousarray(rgb[..., :3]), "depth": depth, "mask": mask}


def compare_renders(
    rendered: Mapping[str, np.ndarray],
    reference: Mapping[str, np.ndarray],
    n_objects: int | None = None,
) -> list[dict[str, float]]:
    """Per-object silhouette IoU and depth error between two renders of the same records.

    Args:
        rendered, reference: dicts with "mask" (H, W) int (record index, -1 background) and
            "depth" (H, W) [m], e.g. two `render_scene` results.
        n_objects: report indices 0..n_objects-1 (objects invisible in both get iou 1.0);
            None reports every index visible in either mask.

    Returns:
        One dict per index, sorted: {"index", "iou" in [0, 1], "area_rendered",
        "area_reference" [pixels], "depth_error_median", "depth_error_mean" [m] (absolute,
        over pixels where both show this object with valid depth; NaN when there are none)}.
    """
    ma, mb = np.asarray(rendered["mask"]), np.asarray(reference["mask"])
    da, db = np.asarray(rendered["depth"], float), np.asarray(reference["depth"], float)
    if ma.shape != mb.shape or da.shape != ma.shape or db.shape != mb.shape:
        raise ToolboxError(
            f"mask/depth shapes differ: {ma.shape}, {mb.shape}, {da.shape}, {db.shape}"
        )
    if n_objects is None:
        indices = sorted(int(i) for i in np.union1d(np.unique(ma), np.unique(mb)) if i >= 0)
    else:
        indices = list(range(int(n_objects)))
    out = []
    for i in indices:
        a, b = ma == i, mb == i
        union = int(np.count_nonzero(a | b))
        both = a & b & (da > 0) & (db > 0)
        err = np.abs(da[both] - db[both])
        out.append(
            {
                "index": i,
                "iou": float(np.count_nonzero(a & b) / union) if union else 1.0,
                "area_rendered": int(np.count_nonzero(a)),
                "area_reference": int(np.count_nonzero(b)),
                "depth_error_median": float(np.median(err)) if err.size else float("nan"),
                "depth_error_mean": float(np.mean(err)) if err.size else float("nan"),
            }
        )
    return out


def overlay_mask(rgb: np.ndarray, mask: np.ndarray, *, alpha: float = 0.5) -> np.ndarray:
    """Tint each mask index (H, W) with its own colour over an rgb image (H, W, 3) uint8."""
    img = np.asarray(rgb, dtype=float).copy()
    m = np.asarray(mask)
    if m.shape != img.shape[:2]:
        raise ToolboxError(f"mask shape {m.shape} does not match image {img.shape[:2]}")
    for i in np.unique(m[m >= 0]):
        hue = (int(i) * 0.618034) % 1.0
        color = 255.0 * np.clip(
            np.abs((hue * 6.0 + np.array([0.0, 4.0, 2.0])) % 6.0 - 3.0) - 1.0, 0, 1
        )
        img[m == i] = (1 - alpha) * img[m == i] + alpha * color
    return img.round().astype(np.uint8)


def _resolve(
    index: int, record: Mapping, meshes: Mapping, colors
) -> tuple[object, tuple | None, np.ndarray]:
    """(mesh, colour or None, pose) of one record, checked."""
    try:
        key, rid, pose = record["mesh"], record.get("id"), record["pose"]
    except (KeyError, TypeError, AttributeError):
        raise ToolboxError(f"records[{index}] must be a dict with 'id', 'mesh', 'pose'") from None
    if key not in meshes:
        known = ", ".join(sorted(map(str, meshes))) or "(none)"
        raise ToolboxError(f"records[{index}].mesh {key!r} is not a known mesh; known: {known}")
    T = np.asarray(pose, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ToolboxError(f"records[{index}].pose must be a finite (4, 4) matrix")
    color = None
    if isinstance(colors, Mapping):
        color = colors.get(rid, colors.get(key))
    elif colors is not None:
        if len(colors) != 0 and len(colors) <= index:
            raise ToolboxError(f"colors has {len(colors)} entries, fewer than the records")
        color = colors[index] if len(colors) else None
    if color is not None:
        c = np.asarray(color, dtype=float).reshape(-1)
        if c.shape not in ((3,), (4,)) or np.any(c < 0) or np.any(c > 255):
            raise ToolboxError(f"colour of records[{index}] must be RGB in 0..255, got {color!r}")
        color = tuple(round(float(v)) for v in c[:3])
    return meshes[key], color, T


class _Context:
    """An offscreen renderer plus the meshes uploaded to its OpenGL context."""

    def __init__(self, width: int, height: int) -> None:
        import pyrender

        try:
            self.renderer = pyrender.OffscreenRenderer(width, height)
        except Exception as e:  # PyOpenGL/EGL raise many unrelated types
            platform = os.environ.get("PYOPENGL_PLATFORM")
            raise RendererUnavailableError(
                f"cannot create an offscreen OpenGL context (PYOPENGL_PLATFORM={platform}): {e}; "
                "install Mesa EGL (libegl1, libgl1-mesa-dri) or set PYOPENGL_PLATFORM=osmesa "
                "with libosmesa6 installed"
            ) from e
        self._meshes: OrderedDict[tuple, tuple[object, object]] = OrderedDict()

    def mesh(self, tm, color: tuple | None):
        """The pyrender mesh for a trimesh (keyed by identity and content hash) and colour."""
        import pyrender

        key = (id(tm), hash(tm), color)
        hit = self._meshes.get(key)
        if hit is not None:
            self._meshes.move_to_end(key)
            return hit[1]
        if color is None:
            pm = pyrender.Mesh.from_trimesh(tm, smooth=False)
        else:
            material = pyrender.MetallicRoughnessMaterial(
                baseColorFactor=[*(np.asarray(color) / 255.0), 1.0],
                metallicFactor=0.0,
                roughnessFactor=0.9,
            )
            pm = pyrender.Mesh.from_trimesh(tm, material=material, smooth=False)
        # Keep `tm` alive so that its id cannot be reused by another mesh while cached.
        self._meshes[key] = (tm, pm)
        while len(self._meshes) > _MAX_MESHES:
            self._meshes.popitem(last=False)
        return pm

    def delete(self) -> None:
        """Free this context's GL objects and the context itself.

        Not `OffscreenRenderer.delete()`: its `eglTerminate` would end the display shared by
        every EGL context of the process (the other sizes', MuJoCo's).
        """
        renderer, platform = self.renderer, self.renderer._platform
        platform.make_current()
        renderer._renderer.delete()
        if hasattr(platform, "_egl_context"):
            from OpenGL import EGL

            display = platform._egl_display
            EGL.eglMakeCurrent(display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, EGL.EGL_NO_CONTEXT)
            EGL.eglDestroyContext(display, platform._egl_context)
        else:
            platform.delete_context()
        # Leave nothing for OffscreenRenderer.__del__ to tear down a second time.
        renderer._renderer = None
        renderer._platform = None
        self._meshes.clear()


@contextlib.contextmanager
def _current_context_restored():
    """Give back the thread's previous EGL context (e.g. MuJoCo's) after rendering.

    pyrender makes its context current and leaves it so; releasing it also lets another
    thread render with it next time (an EGL context is current in one thread at most).
    """
    if os.environ.get("PYOPENGL_PLATFORM") != "egl":
        yield
        return
    from OpenGL import EGL

    display = EGL.eglGetCurrentDisplay()
    previous = (
        EGL.eglGetCurrentSurface(EGL.EGL_DRAW),
        EGL.eglGetCurrentSurface(EGL.EGL_READ),
        EGL.eglGetCurrentContext(),
    )
    try:
        yield
    finally:
        if _address(display) and _address(previous[2]):
            EGL.eglMakeCurrent(display, *previous)
        else:
            ours = EGL.eglGetCurrentDisplay()
            if _address(ours):
                EGL.eglMakeCurrent(ours, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, EGL.EGL_NO_CONTEXT)


def _address(handle) -> int:
    """The address of an EGL handle (0 for EGL_NO_*), whatever ctypes wrapper it comes in."""
    return ctypes.cast(handle, ctypes.c_void_p).value or 0


@atexit.register
def _delete_contexts() -> None:
    """Free the cached contexts at exit, before pyrender's own finaliser would eglTerminate
    a display that other libraries (MuJoCo) may still be tearing down."""
    with _LOCK:
        while _CONTEXTS:
            ctx = _CONTEXTS.pop()
            with contextlib.suppress(Exception):  # interpreter teardown: nothing left to tell
                ctx.delete()


def _context(width: int, height: int) -> _Context:
    """The context, drawing at `width` × `height` from now on (with framebuffers, as EGL has,
    pyrender re-makes only its framebuffer on a new size; without, the whole context)."""
    if not _CONTEXTS:
        _CONTEXTS.append(_Context(width, height))
    ctx = _CONTEXTS[0]
    ctx.renderer.viewport_width, ctx.renderer.viewport_height = width, height
    return ctx


def _opencv_projection(
    K: np.ndarray, width: int, height: int, znear: float, zfar: float
) -> np.ndarray:
    """OpenGL projection (4, 4) reproducing the OpenCV intrinsics K, skew included.

    OpenCV puts pixel centres at integer coordinates, OpenGL at half-integers, hence the
    +0.5 on the principal point.
    """
    fx, s, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    P = np.zeros((4, 4))
    P[0] = [2 * fx / width, -2 * s / width, 1 - 2 * (cx + 0.5) / width, 0]
    P[1] = [0, 2 * fy / height, 2 * (cy + 0.5) / height - 1, 0]
    P[2] = [0, 0, (zfar + znear) / (znear - zfar), 2 * zfar * znear / (znear - zfar)]
    P[3] = [0, 0, -1, 0]
    return P


def _make_camera_class():
    import pyrender

    class OpenCVCamera(pyrender.Camera):
        def __init__(self, K: np.ndarray, znear: float, zfar: float) -> None:
            super().__init__(znear=znear, zfar=zfar)
            self.K = np.asarray(K, dtype=float)

        def get_projection_matrix(self, width=None, height=None):
            return _opencv_projection(self.K, width, height, self.znear, self.zfar)

    return OpenCVCamera


class _LazyCamera:
    """Builds the pyrender camera subclass on first use so importing the toolbox needs no GL."""

    _cls = None

    def __call__(self, K, *, znear, zfar):
        if _LazyCamera._cls is None:
            _LazyCamera._cls = _make_camera_class()
        return _LazyCamera._cls(K, znear, zfar)


_OpenCVCamera = _LazyCamera()
