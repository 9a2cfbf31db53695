"""Reports: schema validity, fixed check order, comparable form, Markdown for the prompt."""

from __future__ import annotations

import numpy as np
import pytest

from checks import CheckResult, build_report, comparable, report_markdown
from checks.report import compact_poses, trim_traceback
from contracts import validate
from contracts.errors import ContractError


def checks():
    return [
        CheckResult(name="property.x", category="property", duration_s=0.2),
        CheckResult(name="interface.signature", category="interface", duration_s=0.1),
        CheckResult(
            name="image.y",
            category="image",
            status="failed",
            message="IoU too low",
            metrics={"iou_min": 0.1234567, "nan": float("nan")},
            images=[{"path": "/tmp/x.png", "caption": "overlay"}],
        ),
        CheckResult(
            name="schema.output",
            category="schema",
            status="failed",
            message="not a plan",
            expected={"status": "ok"},
            actual={"status": "maybe"},
            counterexample={"objects": [{"id": "red", "mesh": "cube", "pose": np.eye(4)}]},
            traceback="Traceback (most recent call last):\n" + "x\n" * 3000 + "ValueError: boom",
            seed=7,
        ),
    ]


def test_report_is_valid_ordered_and_names_the_first_failure():
    report = build_report(domain="cubes", function="plan", source="x = 1\n", checks=checks())
    validate("check_report", report)
    assert [c["category"] for c in report["checks"]] == ["interface", "schema", "property", "image"]
    assert report["first_failure"] == "schema.output" and report["passed"] is False
    tb = report["checks"][1]["traceback"]
    assert tb.endswith("ValueError: boom") and len(tb) <= 2500
    assert report["checks"][3]["metrics"] == {"iou_min": 0.123457, "nan": None}


def test_comparable_drops_only_timings():
    a = build_report(domain="cubes", function="plan", source="", checks=checks(), duration_s=1.0)
    later = checks()
    for c in later:
        c.duration_s = 9.0
    b = build_report(domain="cubes", function="plan", source="", checks=later, duration_s=5.0)
    assert a != b and comparable(a) == comparable(b)


def test_passed_must_agree_with_the_checks():
    report = build_report(domain="cubes", function="plan", source="", checks=checks())
    report["passed"] = True
    with pytest.raises(ContractError) as e:
        validate("check_report", report)
    assert e.value.path == "passed"


def test_markdown_is_short_and_specific():
    report = build_report(domain="cubes", function="plan", source="", checks=checks())
    md = report_markdown(report)
    assert "failed 2 of 4 checks" in md
    assert "### First failure: `schema.output` (schema)" in md
    assert '"status": "maybe"' in md and "seed 7" in md
    assert '"xyz_m": [0.0, 0.0, 0.0], "yaw_deg": 0.0' in md  # poses compacted
    assert "`image.y` (image): IoU too low" in md
    assert len(md) < 6000


def test_markdown_of_a_pass_is_one_line():
    ok = build_report(
        domain="cubes",
        function="relate",
        source="",
        checks=[CheckResult(name="interface.signature", category="interface")],
    )
    assert report_markdown(ok) == "**`relate` passed all 1 checks** (cubes)."


def test_compact_poses_keeps_tilted_rotations():
    tilted = np.eye(4)
    tilted[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    out = compact_poses({"pose": tilted, "other": [1, 2]})
    assert "R" in out["pose"] and out["other"] == [1, 2]


def test_trim_traceback_keeps_the_end():
    assert trim_traceback("a" * 10, 100) == "a" * 10
    assert trim_traceback("x" * 5000 + "END", 100).endswith("END")
