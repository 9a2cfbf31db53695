"""The executor runs a transfer's phases by their segments' labels (`sim._motion.split_at`),
not by where they stand in the list."""

from __future__ import annotations

import numpy as np
import pytest

from sim._motion import PlannedSegment, Segment, split_at


def _planned(*labels: str) -> list[PlannedSegment]:
    return [
        PlannedSegment(segment=Segment(label=label, duration=0.1), q=np.zeros((1, 7)), grip=None)
        for label in labels
    ]


def _labels(runs):
    return [[p.segment.label for p in run] for run in runs]


def test_cut_before_each_label_in_order():
    pick = _planned(
        "rising", "moving above", "descending", "reaching", "closing", "squeezing", "lifting"
    )
    assert _labels(split_at(pick, "closing", "lifting")) == [
        ["rising", "moving above", "descending", "reaching"],
        ["closing", "squeezing"],
        ["lifting"],
    ]
    # an approach without the rise is cut the same way: positions differ, labels do not
    assert _labels(split_at(pick[1:], "closing", "lifting"))[1:] == [
        ["closing", "squeezing"],
        ["lifting"],
    ]


def test_a_missing_or_misordered_label_is_an_error():
    place = _planned("transferring", "descending", "reaching")
    with pytest.raises(ValueError, match="no segment 'opening'"):
        split_at(place, "descending", "opening")
    with pytest.raises(ValueError, match="no segment 'descending'"):
        split_at(place, "reaching", "descending")


def test_the_planner_labels_what_the_executor_cuts_at():
    """The labels the executor cuts at are the planner's own, in the order it cuts."""
    import inspect

    from sim import transfer

    source = inspect.getsource(transfer.TransferPlanner)
    names = ("CLOSING", "LIFTING", "DESCENDING", "REACHING", "SETTLING", "RETREATING")
    positions = [source.index(f"label={n}") for n in names]
    assert positions[:2] == sorted(positions[:2]) and positions[2:] == sorted(positions[2:])
