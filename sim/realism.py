"""Realistic observations: the camera's sensor, the lab's lights and the camera calibration.

One config, `Realism`, with three levels (`LEVELS`; docs/observations.md has the table and
the reasoning behind every value):

- `clean` — the oracle-sensing protocol's images: the clean MuJoCo render under the nominal lights,
  the stereo depth model `DEFAULT_NOISE`, and a perfectly calibrated camera. Its images are
  bit-identical to ``observe(domain, scene, camera, noise=DEFAULT_NOISE, seed=s)``.
- `default` — a ZED 2i (the front observation camera) in a normally lit lab: RGB shot and
  read noise, auto-exposure and auto-white-balance drift, lights that differ by ±10 % and
  up to 10° between sessions, and an extrinsic calibration that is 2 mm / 0.2° off.
- `harsh` — a dim lab, a badly calibrated or bumped camera: 4× the noise variance, ±0.5
  stop exposure, ±10 % white balance, lights up to 30° and ±25 % off, a noisier depth
  model, 5 mm / 0.5° calibration error.

What is applied to one observation (all seeded, so the same seed gives the same image):

1. lights (`vary_lighting`): every light's direction turns by an angle drawn uniformly in
   [0, `light_tilt`] about a random axis (its position turns about the point where its axis
   meets the table, so the shadow map still covers the workspace); every light's intensity
   and the ambient light are scaled by exp(U(-g, g)). The model is changed for that one
   render and restored afterwards (no recompilation).
2. the image is rendered from the TRUE camera;
3. RGB sensor (`sensor_rgb`): the 8-bit render is taken as sRGB, linearised; a global
   exposure gain 2^U(-e, e) [stops]; shot noise (Poisson, as Gaussian with variance s / N
   where N is the photo-electron count at full scale) and read noise (Gaussian, σ = `read_noise`
   of full scale); clipping at full scale (saturation); white-balance gains exp(U(-w, w))
   on red and blue relative to green; sRGB encoding and rounding to 8 bits;
4. depth: the stereo depth model (`DepthNoise`, `apply_depth_noise`), seeded with
   ``np.random.default_rng(seed)`` exactly as before, so depth does not depend on the level's
   RGB settings (only on its depth model);
5. calibration (`calibrated_camera`): the camera returned with the observation — the one a
   robot knows and `perceive` gets — is the true camera moved by exactly `calib_translation`
   [m] in a uniformly random direction and turned by exactly `calib_rotation` [rad] about a
   uniformly random axis through its centre (a calibration that is off by that much, in a
   direction nobody knows). Intrinsics are exact.

Random streams: depth uses ``default_rng(seed)``; the lights ``default_rng([seed, 1])``,
exposure and white balance ``default_rng([seed, 2])``, the pixel noise
``default_rng([seed, 3])``, the calibration ``default_rng([calibration_seed, 4])``. One
camera has one calibration: give the start and the goal observation of a trial the same
`calibration_seed` (``sim.observation.observe`` defaults it to `seed`).

The API is in `sim.observation`: ``observe(domain, scene, camera, seed=s, realism="default")``
returns the observation for `perceive` (its "camera" is the calibrated camera);
``observe_with_truth(...)`` returns ``(observation, truth)`` where ``truth["camera"]`` is the
true camera — host-only, never given to a policy.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import cv2
import numpy as np

from contracts.errors import UsageError
from sim.scene import Lighting

# -- depth ----------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class DepthNoise:
    """Stereo depth sensor model (see sim.observation's docstring); all lengths in metres."""

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
# A ZED 2i in a dim lab on weakly textured surfaces: ≈1.7× the noise, more holes.
HARSH_NOISE = DepthNoise(
    sigma_base=0.001, sigma_quadratic=0.002, edge_dropout=0.85, speckle_dropout=0.01
)


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


# -- the config -----------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class Realism:
    """How far an observation is from the clean render; every effect off by default.

    Attributes (the distributions are in the module docstring):
        name: the level's name (for messages and records).
        full_scale_electrons: photo-electrons per output pixel at full scale (shot noise);
            `math.inf` for none.
        read_noise: σ of the read (and quantisation-independent) noise, fraction of full
            scale, in linear intensity.
        exposure: bound e of the global exposure gain 2^U(-e, e) [stops].
        white_balance: bound w of the red and blue gains exp(U(-w, w)) relative to green.
        light_tilt: bound of each light's direction change [rad].
        light_gain: bound g of each light's intensity scale exp(U(-g, g)).
        ambient_gain: bound of the ambient (headlight) light's scale exp(U(-a, a)).
        depth: the stereo depth model; None for the clean depth.
        calib_translation: position error of the calibrated camera [m] (exact magnitude).
        calib_rotation: rotation error of the calibrated camera [rad] (exact magnitude).
    """

    name: str = "custom"
    full_scale_electrons: float = math.inf
    read_noise: float = 0.0
    exposure: float = 0.0
    white_balance: float = 0.0
    light_tilt: float = 0.0
    light_gain: float = 0.0
    ambient_gain: float = 0.0
    depth: DepthNoise | None = DEFAULT_NOISE
    calib_translation: float = 0.0
    calib_rotation: float = 0.0

    def __post_init__(self) -> None:
        for f in (
            "full_scale_electrons",
            "read_noise",
            "exposure",
            "white_balance",
            "light_tilt",
            "light_gain",
            "ambient_gain",
            "calib_translation",
            "calib_rotation",
        ):
            v = getattr(self, f)
            if not isinstance(v, int | float) or math.isnan(v) or v < 0:
                raise UsageError(f"realism {self.name!r}: {f} must be a number ≥ 0, got {v!r}")
        if self.full_scale_electrons == 0:
            raise UsageError(f"realism {self.name!r}: full_scale_electrons must be > 0")
        if self.light_tilt > math.radians(60):
            raise UsageError(f"realism {self.name!r}: light_tilt must be ≤ 60°")

    @property
    def varies_rgb(self) -> bool:
        """Whether the sensor changes the rendered RGB (False: the render is returned as is)."""
        return (
            math.isfinite(self.full_scale_electrons)
            or self.read_noise > 0
            or self.exposure > 0
            or self.white_balance > 0
        )

    @property
    def varies_lights(self) -> bool:
        return self.light_tilt > 0 or self.light_gain > 0 or self.ambient_gain > 0

    @property
    def miscalibrated(self) -> bool:
        return self.calib_translation > 0 or self.calib_rotation > 0


CLEAN = Realism(name="clean")
DEFAULT = Realism(
    name="default",
    full_scale_electrons=2000.0,
    read_noise=0.002,
    exposure=0.2,
    white_balance=0.04,
    light_tilt=math.radians(10.0),
    light_gain=0.1,
    ambient_gain=0.1,
    depth=DEFAULT_NOISE,
    calib_translation=0.002,
    calib_rotation=math.radians(0.2),
)
HARSH = Realism(
    name="harsh",
    full_scale_electrons=500.0,
    read_noise=0.005,
    exposure=0.5,
    white_balance=0.10,
    light_tilt=math.radians(30.0),
    light_gain=0.25,
    ambient_gain=0.25,
    depth=HARSH_NOISE,
    calib_translation=0.005,
    calib_rotation=math.radians(0.5),
)
LEVELS: dict[str, Realism] = {r.name: r for r in (CLEAN, DEFAULT, HARSH)}


def realism(level: str | Realism | None) -> Realism:
    """The config of a level name (clean, default, harsh), or `level` itself; None is clean."""
    if level is None:
        return CLEAN
    if isinstance(level, Realism):
        return level
    if isinstance(level, str) and level in LEVELS:
        return LEVELS[level]
    raise UsageError(f"unknown realism level {level!r}; known: {', '.join(LEVELS)}")


def with_depth(level: Realism, depth: DepthNoise | None) -> Realism:
    """The level with another depth model (None: clean depth)."""
    return replace(level, depth=depth)


def streams(seed: int, calibration_seed: int | None = None) -> dict[str, np.random.Generator]:
    """The independent random streams of one observation (see the module docstring)."""
    cs = seed if calibration_seed is None else calibration_seed
    for name, v in (("seed", seed), ("calibration_seed", cs)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 0:
            raise UsageError(f"{name} must be an integer ≥ 0, got {v!r}")
    return {
        "depth": np.random.default_rng(seed),
        "lights": np.random.default_rng([seed, 1]),
        "gains": np.random.default_rng([seed, 2]),
        "pixels": np.random.default_rng([seed, 3]),
        "calibration": np.random.default_rng([cs, 4]),
    }


# -- lights ---------------------------------------------------------------------------------


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v)


def _rotation(axis_angle: np.ndarray) -> np.ndarray:
    r, _ = cv2.Rodrigues(np.asarray(axis_angle, float).reshape(3, 1))
    return r


def vary_lighting(nominal: Lighting, rng: np.random.Generator, level: Realism) -> Lighting:
    """Varied lights from the nominal ones (`sim.scene.lighting_of(model)`).

    Every light draws the same random numbers whatever the bounds, so a level's lights
    depend only on the seed and its bounds.
    """
    pos = np.array(nominal.pos, float)
    dirs = np.array(nominal.dir, float)
    diffuse = np.array(nominal.diffuse, float)
    specular = np.array(nominal.specular, float)
    for i in range(nominal.n):
        d = dirs[i] / np.linalg.norm(dirs[i])
        angle = rng.uniform(0.0, 1.0) * level.light_tilt
        axis = np.cross(d, _unit(rng))
        axis /= np.linalg.norm(axis)
        gain = math.exp(rng.uniform(-1.0, 1.0) * level.light_gain)
        rot = _rotation(axis * angle)
        # pivot: where the light's axis meets the table top (z = 0)
        pivot = pos[i] + d * (-pos[i][2] / d[2]) if d[2] < -1e-6 else pos[i]
        pos[i] = pivot + rot @ (pos[i] - pivot)
        dirs[i] = rot @ d
        diffuse[i] = diffuse[i] * gain
        specular[i] = specular[i] * gain
    ambient = math.exp(rng.uniform(-1.0, 1.0) * level.ambient_gain)
    headlight = np.array(nominal.headlight, float)
    headlight[:2] = headlight[:2] * ambient
    return Lighting(
        pos=pos,
        dir=dirs,
        diffuse=np.clip(diffuse, 0.0, 1.0),
        specular=np.clip(specular, 0.0, 1.0),
        ambient=np.array(nominal.ambient, float),
        headlight=np.clip(headlight, 0.0, 1.0).astype(np.float32),
    )


# -- RGB sensor -----------------------------------------------------------------------------

_LINEAR = np.where(
    (np.arange(256) / 255.0) <= 0.04045,
    (np.arange(256) / 255.0) / 12.92,
    (((np.arange(256) / 255.0) + 0.055) / 1.055) ** 2.4,
).astype(np.float32)


def srgb_to_linear(rgb: np.ndarray) -> np.ndarray:
    """Linear intensity in [0, 1] (float32) of an 8-bit sRGB image."""
    return _LINEAR[np.asarray(rgb, np.uint8)]


def linear_to_srgb(lin: np.ndarray) -> np.ndarray:
    """8-bit sRGB (rounded) of linear intensities (clipped to [0, 1])."""
    # in place where it can be (the plain expression's values): a 1280×720 observation is
    # 11 MB as float32, and the plain expression's temporaries were a recorded trial's peak
    x = np.clip(lin, 0.0, 1.0).astype(np.float32, copy=False)
    dark = x <= 0.0031308
    out = np.power(x, 1 / 2.4)
    out *= 1.055
    out -= 0.055
    out[dark] = 12.92 * x[dark]
    out *= 255.0
    return np.round(out, out=out).astype(np.uint8)


def draw_gains(rng: np.random.Generator, level: Realism) -> tuple[float, np.ndarray]:
    """(exposure gain, white-balance gains (3,)) of one observation."""
    u = rng.uniform(-1.0, 1.0, 3)
    exposure = 2.0 ** (u[0] * level.exposure)
    wb = np.array([math.exp(u[1] * level.white_balance), 1.0, math.exp(u[2] * level.white_balance)])
    return exposure, wb


def sensor_rgb(
    rgb: np.ndarray,
    rng: np.random.Generator,
    level: Realism,
    *,
    exposure: float = 1.0,
    white_balance: np.ndarray | None = None,
) -> np.ndarray:
    """The 8-bit image the camera delivers for a clean render `rgb` (see the module docstring).

    Args:
        rng: draws the pixel noise.
        exposure, white_balance: this observation's gains (`draw_gains`).
    """
    # each step in place (the values of the plain expressions, a third of their memory)
    s = srgb_to_linear(rgb)
    s *= np.float32(exposure)
    var: np.ndarray = np.full(s.shape, level.read_noise**2, np.float32)
    if math.isfinite(level.full_scale_electrons):
        shot = np.maximum(s, 0.0)
        shot /= np.float32(level.full_scale_electrons)
        var += shot
        del shot
    noise = rng.standard_normal(s.shape, dtype=np.float32)
    noise *= np.sqrt(var, out=var)
    del var
    s += noise
    del noise
    np.clip(s, 0.0, 1.0, out=s)  # the sensor saturates
    if white_balance is not None:
        s *= np.asarray(white_balance, np.float32)
    return linear_to_srgb(s)


# -- calibration ----------------------------------------------------------------------------


def calibrated_camera(camera: Mapping, rng: np.random.Generator, level: Realism) -> dict:
    """The camera a robot knows: `camera` with the level's calibration error (see above).

    Always draws the same random numbers, so the error direction depends only on the seed.
    """
    t_dir, r_axis = _unit(rng), _unit(rng)
    t = np.array(camera["T_world_camera"], float)
    out = {
        "width": int(camera["width"]),
        "height": int(camera["height"]),
        "K": np.array(camera["K"], float),
        "T_world_camera": t,
    }
    if not level.miscalibrated:
        return out
    t = t.copy()
    t[:3, :3] = t[:3, :3] @ _rotation(r_axis * level.calib_rotation)
    t[:3, 3] = t[:3, 3] + t_dir * level.calib_translation
    out["T_world_camera"] = t
    return out


def calibration_error(calibrated: Mapping, true: Mapping) -> tuple[float, float]:
    """(translation [m], rotation [rad]) between two cameras' poses."""
    a = np.asarray(calibrated["T_world_camera"], float)
    b = np.asarray(true["T_world_camera"], float)
    dt = float(np.linalg.norm(a[:3, 3] - b[:3, 3]))
    w, _ = cv2.Rodrigues(b[:3, :3].T @ a[:3, :3])
    return dt, float(np.linalg.norm(w))


__all__ = [
    "CLEAN",
    "DEFAULT",
    "DEFAULT_NOISE",
    "HARSH",
    "HARSH_NOISE",
    "LEVELS",
    "DepthNoise",
    "Realism",
    "apply_depth_noise",
    "calibrated_camera",
    "calibration_error",
    "draw_gains",
    "linear_to_srgb",
    "realism",
    "sensor_rgb",
    "srgb_to_linear",
    "streams",
    "vary_lighting",
    "with_depth",
]
