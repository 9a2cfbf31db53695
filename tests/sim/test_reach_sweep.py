"""The workspace promise on a coarse grid: every cube pose inside the workspace has a grasp the
executor's IK reaches (`benchmarks.reach_sweep`; the full sweep is a benchmark)."""

from __future__ import annotations

from benchmarks.reach_sweep import sweep


def test_every_cube_pose_in_the_workspace_has_a_reachable_grasp():
    tried, bad = sweep("cubes", 0.2)
    assert tried >= 20 and bad == []
