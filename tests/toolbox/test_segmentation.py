"""Colour and depth segmentation."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from tests.toolbox.conftest import look_at_camera
from toolbox.errors import ToolboxError
from toolbox.geometry import pose_from_xyz_yaw
from toolbox.render import render_scene
from toolbox.segmentation import (
    clean_mask,
    connected_components,
    mask_contour,
    mask_iou,
    rgb_to_hsv,
    segment_above_plane,
    segment_colored_objects,
    segment_hue,
)
from toolbox.vision import estimate_table_plane

COLOURS = {
    "red": (220, 30, 30),
    "green": (40, 190, 60),
    "blue": (40, 60, 210),
    "yellow": (230, 210, 40),
}


def tabletop():
    """Four coloured cubes on a grey table slab, rendered (rgb, depth, mask, camera)."""
    cube = trimesh.creation.box((0.04, 0.04, 0.04))
    table = trimesh.creation.box((0.6, 0.6, 0.02))
    recs = [{"id": "table", "mesh": "table", "pose": pose_from_xyz_yaw(0, 0, -0.01, 0)}]
    for i, name in enumerate(COLOURS):
        recs.append(
            {
                "id": name,
                "mesh": "cube",
                "pose": pose_from_xyz_yaw(-0.12 + 0.08 * i, 0.03 * (i % 2), 0.02, 0.3 * i),
            }
        )
    colors = [(128, 128, 128), *COLOURS.values()]
    cam = look_at_camera((0.0, -0.45, 0.55), (0.0, 0.0, 0.0), width=320, height=240, f=320.0)
    out = render_scene(recs, {"cube": cube, "table": table}, cam, colors=colors)
    return out, cam


def test_coloured_cubes_are_found_one_region_each():
    out, _ = tabletop()
    regions = segment_colored_objects(out["rgb"], min_area=30)
    assert len(regions) == 4
    for r in regions:
        truth = out["mask"] == 1 + int(
            np.argmax([mask_iou(r.mask, out["mask"] == k) for k in range(1, 5)])
        )
        assert mask_iou(r.mask, truth) > 0.9
        assert r.area == np.count_nonzero(r.mask)
        u0, v0, u1, v1 = r.bbox
        assert u0 <= r.centroid[0] <= u1 and v0 <= r.centroid[1] <= v1
    assert [r.area for r in regions] == sorted((r.area for r in regions), reverse=True)


def test_nothing_coloured_gives_no_regions():
    assert segment_colored_objects(np.full((20, 20, 3), 128, np.uint8)) == []


def test_hue_ranges_wrap_through_red():
    img = np.zeros((1, 4, 3), np.uint8)
    img[0] = [(255, 0, 10), (255, 10, 0), (0, 255, 0), (128, 128, 128)]
    hsv = rgb_to_hsv(img)
    assert hsv[0, 2, 0] == pytest.approx(120, abs=1) and hsv[0, 3, 1] == pytest.approx(0)
    np.testing.assert_array_equal(segment_hue(img, 340, 20)[0], [True, True, False, False])
    np.testing.assert_array_equal(segment_hue(img, 100, 140)[0], [False, False, True, False])
    with pytest.raises(ToolboxError, match="uint8"):
        rgb_to_hsv(img.astype(float))


def test_depth_segmentation_above_the_estimated_table():
    out, cam = tabletop()
    plane, _ = estimate_table_plane(out["depth"], cam)
    above = segment_above_plane(out["depth"], cam, plane, min_height=0.005)
    objects = out["mask"] >= 1
    assert np.count_nonzero(above & ~objects) == 0  # nothing of the table
    assert mask_iou(above, objects) > 0.9  # the lowest 5 mm of each cube is left out
    comps = connected_components(clean_mask(above), min_area=20)
    assert len(comps) == 4


def test_mask_utilities():
    m = np.zeros((30, 30), bool)
    m[5:15, 5:15] = True
    m[20, 20] = True  # a speck
    m[9, 9] = False  # a hole
    assert len(connected_components(m)) == 2
    assert len(connected_components(m, min_area=2)) == 1
    cleaned = clean_mask(m, open_px=1, close_px=0, fill_holes=True)
    assert not cleaned[20, 20] and cleaned[9, 9]
    c = mask_contour(m)
    assert c.shape[1] == 2 and c[:, 0].min() == 5 and c[:, 0].max() == 14
    assert mask_contour(np.zeros((4, 4), bool)).shape == (0, 2)
    assert mask_iou(np.zeros((3, 3)), np.zeros((3, 3))) == 1.0
    with pytest.raises(ToolboxError, match="differ"):
        mask_iou(np.zeros((3, 3)), np.zeros((4, 4)))
