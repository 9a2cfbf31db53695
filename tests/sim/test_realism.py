"""Realistic observations (sim.realism): levels, seeding, the clean protocol, RGB statistics,
calibration error, lights, and camera files (the bounds are docs/observations.md's)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import domains
from contracts.errors import UsageError
from sim import realism as rl
from sim.errors import InvalidCameraError
from sim.observation import (
    CameraFileError,
    apply_depth_noise,
    load_camera,
    observe,
    observe_with_truth,
    renderer_for,
)
from sim.scene import lighting_of, scene_model

DOCS_CAMERAS = Path(__file__).resolve().parents[2] / "docs" / "cameras"
CAMERAS = (str(DOCS_CAMERAS / "left_high.json"), str(DOCS_CAMERAS / "right_low.json"))


@pytest.fixture(scope="module")
def cubes():
    d = domains.load("cubes")
    return d, d.benchmark()[0]


# -- the config -----------------------------------------------------------------------------


def test_levels():
    assert list(rl.LEVELS) == ["clean", "default", "harsh"]
    assert rl.realism(None) is rl.CLEAN and rl.realism("harsh") is rl.HARSH
    assert rl.realism(rl.DEFAULT) is rl.DEFAULT
    clean = rl.CLEAN
    assert not (clean.varies_rgb or clean.varies_lights or clean.miscalibrated)
    assert clean.depth == rl.DEFAULT_NOISE
    assert rl.DEFAULT.depth == rl.DEFAULT_NOISE
    # the documented magnitudes
    assert rl.DEFAULT.calib_translation == 0.002
    assert math.isclose(math.degrees(rl.DEFAULT.calib_rotation), 0.2)
    assert rl.HARSH.calib_translation == 0.005
    assert math.isclose(math.degrees(rl.HARSH.calib_rotation), 0.5)
    for a, b in ((rl.CLEAN, rl.DEFAULT), (rl.DEFAULT, rl.HARSH)):  # harsher, parameter by one
        assert b.full_scale_electrons < a.full_scale_electrons and b.read_noise > a.read_noise
        for f in ("exposure", "white_balance", "light_tilt", "light_gain", "ambient_gain"):
            assert getattr(b, f) > getattr(a, f), f
    with pytest.raises(UsageError, match="unknown realism level 'dirty'; known: clean"):
        rl.realism("dirty")
    with pytest.raises(UsageError, match="read_noise"):
        rl.Realism(read_noise=-0.1)
    with pytest.raises(UsageError, match="seed"):
        rl.streams(-1)


# -- the clean protocol -----------------------------------------------------------------------


@pytest.mark.parametrize("name", domains.names())
def test_clean_is_the_previous_protocol_bit_for_bit(name):
    """`clean` is exactly the render + stereo depth noise seeded with default_rng(seed)."""
    d = domains.load(name)
    inst = d.benchmark()[0]
    cam = d.camera("front")
    sm = scene_model(d, inst.start)
    before = renderer_for(sm.model, cam["width"], cam["height"]).render(sm.data, cam)
    before["depth"] = apply_depth_noise(before["depth"], np.random.default_rng(11))
    observe(d, inst.start, "front", seed=11, realism="harsh")  # varies the lights, restores them
    for kwargs in ({}, {"realism": "clean"}, {"realism": rl.CLEAN, "noise": rl.DEFAULT_NOISE}):
        obs = observe(d, inst.start, "front", seed=11, **kwargs)
        assert np.array_equal(obs["rgb"], before["rgb"]), kwargs
        assert np.array_equal(obs["depth"], before["depth"]), kwargs
        assert np.array_equal(obs["camera"]["T_world_camera"], cam["T_world_camera"])
        assert np.array_equal(obs["camera"]["K"], cam["K"])
    clean_depth = observe(d, inst.start, "front", seed=11, noise=None, realism="clean")["depth"]
    assert np.array_equal(
        clean_depth, renderer_for(sm.model, 1280, 720).render(sm.data, cam)["depth"]
    )


# -- seeding --------------------------------------------------------------------------------


@pytest.mark.parametrize("level", list(rl.LEVELS))
def test_each_level_is_seeded(cubes, level):
    d, inst = cubes
    a, ta = observe_with_truth(d, inst.goal, "view1", seed=5, realism=level)
    b, tb = observe_with_truth(d, inst.goal, "view1", seed=5, realism=level)
    for k in ("rgb", "depth"):
        assert np.array_equal(a[k], b[k]), k
    assert np.array_equal(a["camera"]["T_world_camera"], b["camera"]["T_world_camera"])
    assert ta["exposure"] == tb["exposure"] and ta["realism"] == level
    c = observe(d, inst.goal, "view1", seed=6, realism=level)
    assert not np.array_equal(a["depth"], c["depth"])
    if level != "clean":
        assert not np.array_equal(a["rgb"], c["rgb"])
        assert not np.allclose(a["camera"]["T_world_camera"], c["camera"]["T_world_camera"])


def test_depth_follows_the_seed_not_the_rgb_settings(cubes):
    """The default level's depth is the clean level's (same model, same stream)."""
    d, inst = cubes
    a = observe(d, inst.start, "front", seed=2, realism="clean")
    b = observe(d, inst.start, "front", seed=2, realism="default")
    assert np.array_equal(a["depth"], b["depth"])
    c = observe(d, inst.start, "front", seed=2, realism="default", noise=None)
    assert np.array_equal(c["depth"], observe(d, inst.start, "front", noise=None)["depth"])


def test_harsh_depth_is_noisier(cubes):
    d, inst = cubes
    clean = observe(d, inst.start, "front", noise=None)["depth"]
    errs = {}
    for level in ("default", "harsh"):
        z = observe(d, inst.start, "front", seed=3, realism=level)["depth"]
        both = (z > 0) & (clean > 0)
        errs[level] = ((z - clean)[both].std(), (z == 0).mean())
    assert errs["harsh"][0] > 1.4 * errs["default"][0]
    assert errs["harsh"][1] > errs["default"][1]


# -- RGB ------------------------------------------------------------------------------------

# Documented bounds (docs/observations.md), measured on the cubes reference start, front view.
MEAN_RATIO = {"default": (0.8, 1.2), "harsh": (0.55, 1.5)}
NOISE_DN = {"default": (2.0, 4.0), "harsh": (4.0, 8.0)}


@pytest.mark.parametrize("level", ["default", "harsh"])
def test_rgb_statistics_stay_within_the_documented_bounds(cubes, level):
    d, inst = cubes
    clean = observe(d, inst.start, "front", noise=None, mask=True)
    c = clean["rgb"].astype(float)
    # flat table: background pixels whose clean right neighbour has the same value
    flat = (clean["mask"][:, :-1] == -1) & (np.abs(np.diff(c, axis=1)).max(-1) == 0)
    w = rl.LEVELS[level].white_balance
    for seed in range(6):
        obs = observe(d, inst.start, "front", noise=None, seed=seed, realism=level)
        o = obs["rgb"].astype(float)
        lo, hi = MEAN_RATIO[level]
        assert lo < o.mean() / c.mean() < hi, seed
        sigma = np.diff(o, axis=1)[flat].std() / math.sqrt(2)  # per-pixel noise [8-bit steps]
        lo, hi = NOISE_DN[level]
        assert lo < sigma < hi, (seed, sigma)
        m = o.reshape(-1, 3).mean(0) / c.reshape(-1, 3).mean(0)
        assert abs(math.log(m[0] / m[1])) < w + 0.01 and abs(math.log(m[2] / m[1])) < w + 0.01
        assert not np.array_equal(obs["rgb"], clean["rgb"])
        assert np.array_equal(obs["depth"] > 0, clean["depth"] > 0)  # geometry is unchanged


def test_sensor_model_on_a_flat_grey_image():
    rng = np.random.default_rng(0)
    grey = np.full((400, 400, 3), 128, np.uint8)
    lin = float(rl.srgb_to_linear(np.uint8(128)))
    shot = rl.Realism(full_scale_electrons=1000.0, read_noise=0.003)
    out = rl.sensor_rgb(grey, rng, shot)
    assert out.dtype == np.uint8
    back = rl.srgb_to_linear(out).astype(float)
    expected = math.sqrt(lin / 1000.0 + 0.003**2)
    assert math.isclose(back.std(), expected, rel_tol=0.1)  # shot + read noise, linear
    assert abs(back.mean() - lin) < 0.002
    # without noise the pipeline is exact on 8-bit values and the gains act in linear light
    none = rl.Realism(exposure=1.0)
    assert np.array_equal(rl.sensor_rgb(grey, rng, none), grey)
    lit = rl.srgb_to_linear(rl.sensor_rgb(grey, rng, none, exposure=2.0))
    assert np.allclose(lit, 2 * lin, rtol=0.02)
    wb = rl.srgb_to_linear(rl.sensor_rgb(grey, rng, none, white_balance=np.array([1.1, 1.0, 0.9])))[
        0, 0
    ]
    assert np.allclose(wb / lin, [1.1, 1.0, 0.9], rtol=0.02)
    white = rl.sensor_rgb(np.full((8, 8, 3), 250, np.uint8), rng, none, exposure=1.4)
    assert (white == 255).all()  # saturation
    for level in (rl.DEFAULT, rl.HARSH):
        for seed in range(50):
            e, g = rl.draw_gains(np.random.default_rng([seed, 2]), level)
            assert abs(math.log2(e)) <= level.exposure and g[1] == 1.0
            assert np.all(np.abs(np.log(g)) <= level.white_balance)


def _plain_sensor_rgb(rgb, rng, level, exposure, white_balance):
    """`sensor_rgb` as the plain expressions of docs/observations.md (its temporaries and all):
    the in-place version must give the same bytes, or every recorded figure would move."""
    s = rl.srgb_to_linear(rgb) * np.float32(exposure)
    var = np.full(s.shape, level.read_noise**2, np.float32)
    if math.isfinite(level.full_scale_electrons):
        var += np.maximum(s, 0.0) / np.float32(level.full_scale_electrons)
    s = s + rng.standard_normal(s.shape, dtype=np.float32) * np.sqrt(var).astype(np.float32)
    s = np.clip(s, 0.0, 1.0)
    if white_balance is not None:
        s = s * np.asarray(white_balance, np.float32)
    x = np.clip(s, 0.0, 1.0).astype(np.float32)
    out = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(out * 255.0).astype(np.uint8)


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    level=st.sampled_from(sorted(rl.LEVELS)),
    dark=st.booleans(),
    balanced=st.booleans(),
)
def test_the_sensor_pipeline_is_its_plain_expressions_bit_for_bit(seed, level, dark, balanced):
    g = np.random.default_rng(seed)
    rgb = g.integers(0, 12 if dark else 256, (37, 53, 3), dtype=np.uint8)  # dark: the sRGB toe
    lv = rl.LEVELS[level]
    exposure, wb = rl.draw_gains(g, lv)
    wb = wb if balanced else None
    ours = rl.sensor_rgb(rgb, np.random.default_rng(seed), lv, exposure=exposure, white_balance=wb)
    plain = _plain_sensor_rgb(rgb, np.random.default_rng(seed), lv, exposure, wb)
    assert np.array_equal(ours, plain)


# -- calibration ----------------------------------------------------------------------------


@pytest.mark.parametrize("level", [rl.DEFAULT, rl.HARSH])
def test_calibration_error_has_the_documented_magnitude(level):
    cam = domains.load("cubes").camera("front")
    dirs, axes = [], []
    for seed in range(300):
        cal = rl.calibrated_camera(cam, rl.streams(seed)["calibration"], level)
        dt, dr = rl.calibration_error(cal, cam)
        assert math.isclose(dt, level.calib_translation, rel_tol=1e-6)
        assert math.isclose(dr, level.calib_rotation, rel_tol=1e-6)
        assert np.array_equal(cal["K"], cam["K"]) and cal["width"] == cam["width"]
        r = cal["T_world_camera"][:3, :3]
        assert np.allclose(r.T @ r, np.eye(3), atol=1e-12) and np.linalg.det(r) > 0
        dirs.append(cal["T_world_camera"][:3, 3] - cam["T_world_camera"][:3, 3])
        axes.append(r[:, 2])
    # no preferred direction: the mean offset is small against the magnitude
    assert np.linalg.norm(np.mean(dirs, axis=0)) < 0.2 * level.calib_translation
    assert rl.calibrated_camera(cam, rl.streams(0)["calibration"], rl.CLEAN)["T_world_camera"] == (
        pytest.approx(cam["T_world_camera"], abs=0)
    )


def test_the_observation_carries_the_calibrated_camera_and_the_image_the_true_one(cubes):
    d, inst = cubes
    obs, truth = observe_with_truth(d, inst.start, "front", seed=4, realism="default", mask=True)
    true_cam = d.camera("front")
    assert np.array_equal(truth["camera"]["T_world_camera"], true_cam["T_world_camera"])
    dt, dr = rl.calibration_error(obs["camera"], truth["camera"])
    assert math.isclose(dt, 0.002, rel_tol=1e-6) and math.isclose(dr, math.radians(0.2))
    assert truth["calibration_error"] == pytest.approx((dt, dr))
    clean = observe(d, inst.start, "front", noise=None, mask=True)
    assert np.array_equal(obs["mask"], clean["mask"])  # rendered from the true camera
    # one camera, one calibration: the goal with the same calibration seed has the same error
    goal = observe(d, inst.goal, "front", seed=5, calibration_seed=4, realism="default")
    assert np.array_equal(goal["camera"]["T_world_camera"], obs["camera"]["T_world_camera"])
    other = observe(d, inst.goal, "front", seed=5, realism="default")
    assert not np.array_equal(other["camera"]["T_world_camera"], obs["camera"]["T_world_camera"])


# -- lights ---------------------------------------------------------------------------------


def test_lights_vary_within_bounds_without_recompiling(cubes):
    d, inst = cubes
    sm = scene_model(d, inst.start)
    nominal = lighting_of(sm.model)
    model = sm.model
    for level in (rl.DEFAULT, rl.HARSH):
        for seed in range(30):
            lit = rl.vary_lighting(nominal, rl.streams(seed)["lights"], level)
            for i in range(nominal.n):
                a = nominal.dir[i] / np.linalg.norm(nominal.dir[i])
                b = lit.dir[i] / np.linalg.norm(lit.dir[i])
                assert math.acos(np.clip(a @ b, -1, 1)) <= level.light_tilt + 1e-9
                assert b[2] < -0.15  # still lights the table from above
                gain = lit.diffuse[i] / nominal.diffuse[i]
                assert np.all(np.abs(np.log(gain)) <= level.light_gain + 1e-9)
            amb = lit.headlight[0] / nominal.headlight[0]
            assert np.all(np.abs(np.log(amb)) <= level.ambient_gain + 1e-6)
    observe(d, inst.start, "front", seed=1, realism="harsh")
    assert scene_model(d, inst.start).model is model  # no new model per render
    after = lighting_of(model)
    for f in ("pos", "dir", "diffuse", "specular", "ambient", "headlight"):
        assert np.array_equal(getattr(after, f), getattr(nominal, f)), f


# -- camera files ---------------------------------------------------------------------------


@pytest.mark.parametrize("path", CAMERAS)
def test_example_cameras_see_every_object_of_every_domain(path):
    cam = load_camera(path)
    for name in domains.names():
        d = domains.load(name)
        for view in d.cameras.values():  # none of the named views
            named = view.to_camera()["T_world_camera"][:3, 3]
            assert np.linalg.norm(cam["T_world_camera"][:3, 3] - named) > 0.1
        inst = d.benchmark()[0]
        obs = observe(d, inst.start, path, noise=None, mask=True)
        assert obs["rgb"].shape == (cam["height"], cam["width"], 3)
        n = len(inst.start["objects"])
        counts = np.bincount(obs["mask"][obs["mask"] >= 0], minlength=n)
        assert (counts > 300).all(), (name, counts)  # every object visible, not a sliver
        m = obs["mask"]
        border = np.concatenate([m[0], m[-1], m[:, 0], m[:, -1]])
        assert (border == -1).all(), name  # and none cut by the image border


def test_camera_file_forms(tmp_path):
    view = json.loads(Path(CAMERAS[0]).read_text())
    from domains.catalogue import CameraSpec

    spec = CameraSpec(
        name="x", **{k: tuple(v) if isinstance(v, list) else v for k, v in view.items()}
    )
    a = load_camera(CAMERAS[0])
    assert np.allclose(a["T_world_camera"], spec.to_camera()["T_world_camera"])
    assert np.allclose(a["K"], spec.to_camera()["K"])
    # the DESIGN form, and an observation folder's camera.json (with depth_scale)
    design = {
        "width": 1280,
        "height": 720,
        "K": a["K"].tolist(),
        "T_world_camera": a["T_world_camera"].tolist(),
    }
    (tmp_path / "c.json").write_text(json.dumps({**design, "depth_scale": 0.1}))
    b = load_camera(tmp_path / "c.json")
    assert np.allclose(b["T_world_camera"], a["T_world_camera"]) and b["width"] == 1280


def _bad(tmp_path, value) -> str:
    path = tmp_path / "bad.json"
    path.write_text(value if isinstance(value, str) else json.dumps(value))
    with pytest.raises(CameraFileError) as e:
        load_camera(path)
    assert isinstance(e.value, InvalidCameraError) and isinstance(e.value, UsageError)
    assert str(path) in str(e.value)
    return str(e.value)


def test_bad_camera_files_are_refused(tmp_path):
    good = json.loads(Path(CAMERAS[1]).read_text())
    view = json.loads(Path(CAMERAS[0]).read_text())

    def edit(base, f):
        c = json.loads(json.dumps(base))
        f(c)
        return c

    assert "not JSON" in _bad(tmp_path, "{")
    assert "square pixels" in _bad(tmp_path, edit(good, lambda c: c["K"][0].__setitem__(0, 600)))
    assert "principal point" in _bad(
        tmp_path, edit(good, lambda c: c["K"][0].__setitem__(2, 500.0))
    )
    assert "needs K" in _bad(tmp_path, edit(good, lambda c: c.pop("K")))
    assert "T_world_camera" in _bad(
        tmp_path, edit(good, lambda c: c["T_world_camera"][0].__setitem__(0, 2.0))
    )
    big = edit(good, lambda c: c.update(width=4000))
    big["K"][0][2] = 1999.5
    assert "exceeds" in _bad(tmp_path, big)
    assert "straight up or down" in _bad(
        tmp_path, edit(view, lambda c: c.update(target=[0.7, 0.45, 0.0]))
    )
    assert "fovy" in _bad(tmp_path, edit(view, lambda c: c.update(fovy=190)))
    assert "a camera file holds" in _bad(tmp_path, {"width": 10})
    with pytest.raises(CameraFileError, match="no such camera file"):
        load_camera(tmp_path / "missing.json")
