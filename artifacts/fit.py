"""How well a perceived state explains its observation: what lets `rivet solve` know it is lost.

The perceived records are rendered by the set's own frozen `render` (the function the image
checks hold to the reference renderer) from the observation's calibrated camera, and compared
with the observed depth:

- the observation's *foreground*: pixels whose observed depth, averaged over `SMOOTH_PX` ×
  `SMOOTH_PX` pixels, is in front of the table plane z = 0 by `FOREGROUND_M` or by
  `NOISE_SIGMAS` times the sensor's noise at that depth, whichever is more (something stands
  there). The plane is fitted to the observed table first (the calibration error tilts it by
  a few millimetres), and the noise is measured on the observed table itself, by depth: a
  stereo sensor's noise grows with the square of the distance, and a far table would
  otherwise read as foreground;
- per object, judged on its rendered pixels that stand off the table by more than that
  margin: its *support* — the share of them where the observed depth, pixel by pixel, is at
  least half the margin in front of the table — and its *residual*, the median |observed −
  rendered depth| over them;
- *unexplained*: the share of the foreground no perceived object covers (parts the programs
  did not see, or objects of another domain).

A state fits when every object keeps `SUPPORT_MIN` and `RESIDUAL_MAX_M` and at most
`UNEXPLAINED_MAX` of the foreground is unexplained; `SceneFit.problems` says what does not, worst
first. The bounds sit well outside what the frozen programs produce on the dev split's
observations (docs/api.md, "Images the set does not explain"), so that a refusal means the images are
not of the domain, or the programs are lost on them — not a few millimetres of error.

Design rule: numpy and OpenCV only, like the rest of the thin runtime (no simulator in `rivet
solve`).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from contracts import se3

FOREGROUND_M = 0.004  # [m] in front of the bare table: something is there
SMOOTH_PX = 5  # [px] the depth is averaged over this square before it is compared to the table
NOISE_SIGMAS = 4.0  # the foreground stands this many noise deviations in front of the table
SUPPORT_MIN = 0.5  # per object: share of its rendered pixels where the observation shows something
RESIDUAL_MAX_M = 0.015  # [m] per object: median |observed − rendered depth| on its pixels
UNEXPLAINED_MAX = 0.25  # share of the observed foreground no perceived object covers
MIN_PIXELS = 100  # [px] objects showing fewer inner pixels than this (hidden) are not judged
EDGE_PX = 2  # [px] an object is judged this far in from its rendered outline
PREFER_MARGIN_M = 0.003  # [m] an alternative pose explains an object better when its residual
# is this much smaller (`better_explained`)
LOOSE_PART_SHARE = 0.5  # an unexplained region this share of the smallest judged object's
# pixels is a part standing where nothing was perceived (`SceneFit.loose_part`)


@dataclass(frozen=True, kw_only=True)
class ObjectFit:
    id: str
    mesh: str
    pixels: int  # rendered and visible [px]
    support: float | None  # None: too few pixels to judge
    residual_m: float | None

    def to_dict(self) -> dict:
        return {
            "id": self.id,
            "mesh": self.mesh,
            "pixels": self.pixels,
            "support": None if self.support is None else round(self.support, 3),
            "residual_m": None if self.residual_m is None else round(self.residual_m, 4),
        }


@dataclass(frozen=True, kw_only=True)
class SceneFit:
    objects: list[ObjectFit]
    foreground_px: int
    unexplained: float  # share of the foreground
    problems: list[str]
    mask: np.ndarray  # (H, W) rendered object index, -1 none
    foreground: np.ndarray  # (H, W) bool
    largest_unexplained_px: int = 0  # the largest connected unexplained region [px]

    @property
    def ok(self) -> bool:
        return not self.problems

    def loose_part(self) -> str | None:
        """Something the size of a part stands where nothing was perceived: the largest
        connected unexplained region has at least `LOOSE_PART_SHARE` of the pixels of the
        smallest object judged. A stricter test than `ok`'s share of the whole foreground, for
        a scene whose objects are known to be the domain's (the closed loop's last look: a part
        fallen on its side that `perceive` put elsewhere); `rivet solve` does not refuse by it."""
        judged = [o.pixels for o in self.objects if o.support is not None]
        if not judged or self.largest_unexplained_px < LOOSE_PART_SHARE * min(judged):
            return None
        return (
            f"a region of {self.largest_unexplained_px} px stands above the table where no "
            f"object was perceived (the smallest object judged shows {min(judged)} px)"
        )

    def to_dict(self) -> dict:
        return {
            "ok": self.ok,
            "problems": self.problems,
            "unexplained": round(self.unexplained, 3),
            "largest_unexplained_px": self.largest_unexplained_px,
            "loose_part": self.loose_part(),
            "foreground_px": self.foreground_px,
            "objects": [o.to_dict() for o in self.objects],
        }


Render = Callable[[list[dict], Mapping[str, Any]], Mapping[str, Any]]
"""`render(records, camera) -> {"depth", "mask"}`: the frozen `render` (mask: record index)."""


def scene_fit(
    domain: Any, observation: Mapping[str, Any], records: Sequence[Mapping], render: Render
) -> SceneFit:
    """The fit of `records` (what `perceive` returned) to `observation` (see the module)."""
    camera = observation["camera"]
    depth = np.asarray(observation["depth"], float)
    problems: list[str] = []
    known: list[dict[str, Any]] = []
    unknown: list[str] = []
    for r in records:
        mesh = str(r.get("mesh", ""))
        try:
            T = se3.as_matrix(r["pose"])
        except (KeyError, TypeError, ValueError):
            unknown.append(f"{r.get('id')!r} has no pose")
            continue
        if mesh not in domain.mesh_specs:
            unknown.append(f"{r.get('id')!r} has mesh {mesh!r}, not one of {domain.name}'s")
            continue
        known.append({"id": str(r["id"]), "mesh": mesh, "pose": T.tolist()})
    problems += unknown
    h, w = depth.shape
    table = table_depth(camera, (h, w))
    valid = np.isfinite(depth) & (depth > 0)
    foreground, surface, threshold = _foreground(depth, table, valid)
    mask = np.full((h, w), -1, np.int32)
    rendered = np.zeros((h, w))
    if known:
        images = render(known, camera)
        mask = np.asarray(images["mask"]).astype(np.int32)
        rendered = np.asarray(images["depth"], float)
        if mask.shape != (h, w) or rendered.shape != (h, w):
            raise ValueError(f"the frozen render drew {mask.shape} for a {h}×{w} observation")
    fits = []
    for k, o in enumerate(known):
        # away from its outline: a hidden object's sliver along its occluder's edge, or a pose
        # a few millimetres off, would otherwise be judged on pixels of its neighbours
        # and where it stands clearly off the table: the foot of a side face looks like the
        # table to the sensor whether the object is there or not
        mine = _eroded(mask == k, EDGE_PX) & valid & (surface - rendered > threshold)
        n = int(mine.sum())
        if n < MIN_PIXELS:
            fits.append(ObjectFit(id=o["id"], mesh=o["mesh"], pixels=n, support=None,
                                  residual_m=None))  # fmt: skip
            continue
        # its own pixels, not averaged with the table beside a narrow sliver: something stands
        # there when its depth is half the margin in front of the table (6-11 % of the bare
        # table's pixels pass that through front, view1 and two envelope cameras, dev scenes:
        # far below SUPPORT_MIN)
        support = float((surface[mine] - depth[mine] > threshold[mine] / 2).mean())
        residual = float(np.median(np.abs(depth[mine] - rendered[mine])))
        fits.append(ObjectFit(id=o["id"], mesh=o["mesh"], pixels=n, support=support,
                              residual_m=residual))  # fmt: skip
    for f in sorted(fits, key=lambda f: -(f.residual_m or 0.0)):
        if f.support is not None and f.support < SUPPORT_MIN:
            problems.append(
                f"{f.id!r} ({f.mesh}): only {100 * f.support:.0f} % of where it was perceived "
                f"shows anything above the table (at least {100 * SUPPORT_MIN:.0f} % expected)"
            )
        elif f.residual_m is not None and f.residual_m > RESIDUAL_MAX_M:
            problems.append(
                f"{f.id!r} ({f.mesh}): the observed depth differs from its perceived shape by "
                f"{1000 * f.residual_m:.0f} mm (median; at most {1000 * RESIDUAL_MAX_M:.0f} mm)"
            )
    fg = int(foreground.sum())
    # near a perceived outline the averaged depth and a pose a few millimetres off both blur
    # the edge: those pixels are not counted against the state
    reach = 2 * (EDGE_PX + SMOOTH_PX // 2) + 1
    covered = cv2.dilate((mask >= 0).astype(np.uint8), np.ones((reach, reach), np.uint8)) > 0
    loose = foreground & ~covered
    unexplained = float(loose.sum()) / fg if fg else 0.0
    largest = 0
    if loose.any():
        _, _, stats, _ = cv2.connectedComponentsWithStats(loose.astype(np.uint8), connectivity=8)
        largest = int(stats[1:, cv2.CC_STAT_AREA].max())
    if unexplained > UNEXPLAINED_MAX:
        problems.append(
            f"{100 * unexplained:.0f} % of what stands on the table is explained by no perceived "
            f"object (at most {100 * UNEXPLAINED_MAX:.0f} %): objects missed, or not "
            f"{domain.name} objects"
        )
    if not known and fg:
        problems.insert(0, f"nothing of {domain.name} was perceived, but something stands there")
    return SceneFit(objects=fits, foreground_px=fg, unexplained=unexplained, problems=problems,
                    mask=mask, foreground=foreground, largest_unexplained_px=largest)  # fmt: skip


def better_explained(
    domain: Any,
    observation: Mapping[str, Any],
    records: Sequence[Mapping],
    alternative: Sequence[Mapping],
    render: Render,
) -> list[str]:
    """The ids of the objects whose pose in `alternative` explains `observation` better than
    their pose in `records` (the same objects; some at other poses): what the closed loop asks
    before a look moves a belief (`sim.loop.ClosedLoop`'s referee, with the look as `records`
    and the belief as `alternative`). Each changed object is judged by `prefers`."""
    changed = {
        str(a["id"])
        for a, b in zip(records, alternative, strict=True)
        if not np.allclose(se3.as_matrix(a["pose"]), se3.as_matrix(b["pose"]))
    }
    if not changed:
        return []
    ours = {o.id: o for o in scene_fit(domain, observation, records, render).objects}
    theirs = {o.id: o for o in scene_fit(domain, observation, alternative, render).objects}
    return [i for i in sorted(changed) if prefers(theirs.get(i), ours.get(i))]


def prefers(there: ObjectFit | None, here: ObjectFit | None) -> bool:
    """Whether an object's fit `there` (at its alternative pose) explains the image better than
    its fit `here`; None, or no support, where it is hidden.

    - Judged `there` (enough visible pixels) and fitting there (`SUPPORT_MIN`,
      `RESIDUAL_MAX_M`): better when, `here`, it is hidden, lacks support, or its residual is
      over `PREFER_MARGIN_M` larger.
    - Hidden `there`, the image says nothing for that pose: better only when `here` is judged
      and contradicted — the pixels where `here` puts the object show something else (it lacks
      support or its residual is over `RESIDUAL_MAX_M`). A reading the image refutes does not
      beat one it cannot see.
    - Judged `there` and not fitting: never better."""
    t, h = _judged(there), _judged(here)
    if t is None:
        return h is not None and (h[0] < SUPPORT_MIN or h[1] > RESIDUAL_MAX_M)
    if t[0] < SUPPORT_MIN or t[1] > RESIDUAL_MAX_M:
        return False
    return h is None or h[0] < SUPPORT_MIN or h[1] > t[1] + PREFER_MARGIN_M


def _judged(fit: ObjectFit | None) -> tuple[float, float] | None:
    """(support, residual [m]) of an object the image shows enough of to judge; else None."""
    if fit is None or fit.support is None or fit.residual_m is None:
        return None
    return fit.support, fit.residual_m


def _eroded(mask: np.ndarray, px: int) -> np.ndarray:
    """`mask` without the pixels within `px` 4-connected steps of its outline (or the image's
    edge)."""
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    inner = cv2.erode(
        mask.astype(np.uint8), cross, iterations=px, borderType=cv2.BORDER_CONSTANT, borderValue=0
    )
    return inner.astype(bool)


def table_depth(camera: Mapping[str, Any], shape: tuple[int, int]) -> np.ndarray:
    """Depth [m] of the table plane z = 0 at each pixel of `camera` (0 where it is not seen)."""
    h, w = shape
    K = np.asarray(camera["K"], float)
    T = np.asarray(camera["T_world_camera"], float)
    v, u = np.mgrid[0:h, 0:w].astype(float)
    y = (v - K[1, 2]) / K[1, 1]
    x = (u - K[0, 2] - K[0, 1] * y) / K[0, 0]
    ray_z = T[2, 0] * x + T[2, 1] * y + T[2, 2]  # world z per unit of depth
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = -T[2, 3] / ray_z
    return np.where(np.isfinite(depth) & (depth > 0), depth, 0.0)


def _foreground(
    depth: np.ndarray, table: np.ndarray, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(foreground, surface, threshold): the pixels where something stands in front of the
    table (see the module docstring), the fitted table's depth [m] and the margin in front
    of it [m] that counts, per pixel. A pixel most of whose neighbourhood has no depth (an
    edge the sensor drops) is not foreground: too little is known there."""
    k = (SMOOTH_PX, SMOOTH_PX)
    weight = cv2.blur(valid.astype(np.float32), k)
    smooth = cv2.blur(np.where(valid, depth, 0.0).astype(np.float32), k) / np.maximum(weight, 1e-6)
    surface = table + _table_offset(depth, table)
    height = surface - smooth  # [m] in front of the fitted table
    on_table = valid & (table > 0)
    threshold = np.maximum(FOREGROUND_M, NOISE_SIGMAS * _noise(height, smooth, on_table))
    return on_table & (weight > 0.5) & (height > threshold), surface, threshold


def _noise(
    height: np.ndarray, depth: np.ndarray, on_table: np.ndarray, bins: int = 8
) -> np.ndarray:
    """Per pixel, the standard deviation [m] of `height` over the bare table at that pixel's
    depth z, as a + b z² (a stereo sensor's noise grows with the square of the distance),
    fitted to a robust spread (1.4826 × the median absolute deviation) of the table's pixels
    in `bins` depth bands. What stands on the table (a minority of its pixels) barely moves a
    median."""
    sel = on_table & (np.abs(height) < 0.02)
    z, r = depth[sel][::7], height[sel][::7]  # a sample is enough
    if z.size < 100 * bins:
        return np.zeros_like(depth)
    edges = np.quantile(z, np.linspace(0, 1, bins + 1))
    centres, sigmas = [], []
    for lo, hi in itertools.pairwise(edges):
        inside = (z >= lo) & (z <= hi)
        if inside.sum() >= 50:
            band = r[inside]
            centres.append(float(np.median(z[inside])))
            sigmas.append(1.4826 * float(np.median(np.abs(band - np.median(band)))))
    if len(centres) < 2:
        return np.full_like(depth, max(sigmas, default=0.0))
    zc = np.asarray(centres)
    (a, b), *_ = np.linalg.lstsq(np.stack([np.ones_like(zc), zc**2], 1), sigmas, rcond=None)
    if b < 0:  # no growth seen: the spread of the bands
        a, b = max(sigmas), 0.0
    return np.maximum(a, 0.0) + b * np.square(depth)


def _table_offset(depth: np.ndarray, table: np.ndarray, step: int = 4) -> np.ndarray:
    """Where the observed table lies relative to the table plane's depth, per pixel (an affine
    fit in the image on every `step`-th pixel, robust to what stands on it): the calibrated
    camera is off the true one by a few millimetres and tenths of a degree, which tilts the
    whole table in depth."""
    h, w = depth.shape
    r = (depth - table)[::step, ::step]
    v, u = np.mgrid[0:h:step, 0:w:step]
    use = np.isfinite(r) & (depth[::step, ::step] > 0) & (table[::step, ::step] > 0)
    use &= np.abs(r) < 0.02
    A = np.stack([np.ones(u.size), u.ravel() / w, v.ravel() / h], axis=1)
    coef = np.zeros(3)
    for tol in (0.01, 0.004, 0.002):
        sel = use.ravel()
        if sel.sum() < 100:
            break
        coef, *_ = np.linalg.lstsq(A[sel], r.ravel()[sel], rcond=None)
        use = use & (np.abs(r - (A @ coef).reshape(r.shape)) < tol)
    V, U = np.mgrid[0:h, 0:w]
    return coef[0] + coef[1] * U / w + coef[2] * V / h


def fit_overlay(observation: Mapping[str, Any], fit: SceneFit) -> np.ndarray:
    """The observation with each perceived object's silhouette tinted over it (labelled with
    its id) and the foreground no object explains in magenta: what a person checks a refusal,
    or a plan, by."""
    import cv2

    from checks.images import tint

    out = tint(np.asarray(observation["rgb"], np.uint8), fit.mask, alpha=0.45)
    out[fit.foreground & (fit.mask < 0)] = (255, 0, 255)
    for k, o in enumerate(fit.objects):
        ys, xs = np.nonzero(fit.mask == k)
        if len(xs):
            label = "".join(c if 32 <= ord(c) < 127 else "?" for c in o.id)
            at = (int(xs.mean()) - 4 * len(label), int(ys.mean()))
            cv2.putText(out, label, at, cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 3, cv2.LINE_AA)
            cv2.putText(out, label, at, cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1,
                        cv2.LINE_AA)  # fmt: skip
    return out
