"""RGB-D observations: geometry of the image, the depth sensor model, the folder format."""

from __future__ import annotations

import numpy as np
import pytest

import domains
from artifacts.observations import read_observation, write_observation
from sim.errors import InvalidCameraError
from sim.observation import DepthNoise, apply_depth_noise, observe


@pytest.fixture(scope="module", params=domains.names())
def reference(request):
    d = domains.load(request.param)
    return d, d.benchmark()[0]


def test_observation_shapes_and_types(reference):
    d, inst = reference
    obs = observe(d, inst.goal, "front", mask=True)
    assert obs["rgb"].shape == (720, 1280, 3) and obs["rgb"].dtype == np.uint8
    assert obs["depth"].shape == (720, 1280) and obs["depth"].dtype == np.float32
    assert obs["mask"].dtype == np.int32
    # every object of the reference goal is visible from the default camera
    assert set(np.unique(obs["mask"])) - {-1} == set(range(len(inst.goal["objects"])))


def test_projection_matches_the_rendered_image(reference):
    """Each object's visible pixels back-project (with the clean depth) onto its own mesh."""
    d, inst = reference
    obs = observe(d, inst.goal, "front", noise=None, mask=True)
    k, t = obs["camera"]["K"], obs["camera"]["T_world_camera"]
    for idx, rec in enumerate(inst.goal["objects"]):
        v, u = np.nonzero(obs["mask"] == idx)
        if len(u) < 50:
            continue
        z = obs["depth"][v, u]
        rays = np.linalg.inv(k) @ np.stack([u, v, np.ones_like(u)]).astype(float)
        pts = (t[:3, :3] @ (rays * z) + t[:3, 3:4]).T  # (n, 3) world
        local = (np.linalg.inv(rec["pose"]) @ np.c_[pts, np.ones(len(pts))].T).T[:, :3]
        mesh = d.mesh(rec["mesh"])
        lo, hi = mesh.bounds
        inside = np.all((local >= lo - 0.002) & (local <= hi + 0.002), axis=1)
        assert inside.mean() > 0.98, rec["id"]


def test_depth_round_trips_through_the_folder_within_1mm(reference, tmp_path):
    d, inst = reference
    clean = observe(d, inst.start, "view1", noise=None)
    back = read_observation(write_observation(clean, tmp_path / "obs"))
    assert np.array_equal(back["rgb"], clean["rgb"])
    assert np.array_equal(back["depth"] > 0, clean["depth"] > 0)
    assert np.abs(back["depth"] - clean["depth"]).max() < 0.001
    assert np.allclose(back["camera"]["K"], clean["camera"]["K"])
    assert np.allclose(back["camera"]["T_world_camera"], clean["camera"]["T_world_camera"])


def test_noisy_depth_stays_near_the_clean_depth(reference, tmp_path):
    d, inst = reference
    clean = observe(d, inst.start, "front", noise=None)
    noisy = read_observation(write_observation(observe(d, inst.start, "front", seed=3), tmp_path))
    both = (clean["depth"] > 0) & (noisy["depth"] > 0)
    err = noisy["depth"][both] - clean["depth"][both]
    assert abs(err.mean()) < 2e-4
    assert 0.0008 < err.std() < 0.003  # 1–2 mm of noise, with quantisation
    assert (noisy["depth"] == 0).mean() > (clean["depth"] == 0).mean()  # missing pixels


def test_noise_model():
    model = DepthNoise()
    rng = np.random.default_rng(0)
    z = np.full((200, 200), 0.8, np.float32)
    z[:, 100:] = 1.2  # a depth edge
    n = apply_depth_noise(z, rng, model)
    left, right = n[:, :90], n[:, 110:]
    assert np.isclose(left[left > 0].std(), model.sigma(0.8), rtol=0.15)
    assert np.isclose(right[right > 0].std(), model.sigma(1.2), rtol=0.15)
    assert np.allclose(np.round(n[n > 0] / 0.001) * 0.001, n[n > 0], atol=1e-6)  # 1 mm steps
    assert (n[:, 99:101] == 0).mean() > 0.5  # missing at the edge
    assert (left == 0).mean() < 0.01
    assert np.array_equal(n, apply_depth_noise(z, np.random.default_rng(0), model))


def test_observations_are_reproducible(reference):
    d, inst = reference
    a = observe(d, inst.goal, "view2", seed=5)
    b = observe(d, inst.goal, "view2", seed=5)
    assert np.array_equal(a["rgb"], b["rgb"]) and np.array_equal(a["depth"], b["depth"])


def test_camera_dicts_render_like_named_cameras(reference):
    d, inst = reference
    cam = d.camera("view1")
    a = observe(d, inst.goal, "view1", noise=None)
    b = observe(
        d,
        inst.goal,
        {**cam, "K": cam["K"].tolist(), "T_world_camera": cam["T_world_camera"].tolist()},
        noise=None,
    )
    assert np.array_equal(a["depth"], b["depth"])


def test_cameras_mujoco_cannot_render_are_refused():
    d = domains.load("cubes")
    inst = d.benchmark()[0]
    cam = d.camera("front")
    cam["K"] = cam["K"].copy()
    cam["K"][0, 2] += 20
    with pytest.raises(InvalidCameraError, match="principal point"):
        observe(d, inst.goal, cam)


def test_one_pass_gives_the_depth_and_the_mask_of_two(reference):
    """With a mask, the depth pass's colour buffer gives the segmentation (`_segments_drawn`):
    the same depth and mask, byte for byte, as a depth pass and a segmentation pass apart —
    and the same pass of a segmentation render."""
    from sim.observation import _segments_drawn, renderer_for
    from sim.scene import scene_model

    d, inst = reference
    sm = scene_model(d, inst.goal)
    cam = d.camera("view1")
    r = renderer_for(sm.model, cam["width"], cam["height"])
    ids = [o["id"] for o in inst.goal["objects"]]
    both = r.render(sm.data, cam, depth=True, mask=True, mask_ids=ids)
    depth = r.render(sm.data, cam, depth=True, mask=False)
    mask = r.render(sm.data, cam, depth=False, mask=True, mask_ids=ids)  # a pass of its own
    assert np.array_equal(both["depth"], depth["depth"])
    assert np.array_equal(both["mask"], mask["mask"])
    assert np.array_equal(both["rgb"], mask["rgb"])
    assert set(np.unique(both["mask"])) - {-1} == set(range(len(ids)))
    gl = r._gl
    gl.enable_segmentation_rendering()
    try:
        seg = gl.render()  # the scene the last pass drew, drawn again as a segmentation
    finally:
        gl.disable_segmentation_rendering()
    assert np.array_equal(_segments_drawn(gl), seg)
