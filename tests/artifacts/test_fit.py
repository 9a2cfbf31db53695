"""`SceneFit.loose_part`: a region no perceived object explains, as large as a part, is named —
judged against the smallest object the fit could judge, not against the whole foreground.
`prefers`: when the closed loop's referee keeps a belief against a look."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from artifacts.fit import (
    LOOSE_PART_SHARE,
    PREFER_MARGIN_M,
    RESIDUAL_MAX_M,
    SUPPORT_MIN,
    ObjectFit,
    SceneFit,
    prefers,
)


def _fit(largest: int, *pixels: int | None) -> SceneFit:
    def judged(k: int, n: int | None) -> ObjectFit:
        if n is None:  # hidden: too few pixels to judge
            return ObjectFit(id=f"o{k}", mesh="m", pixels=0, support=None, residual_m=None)
        return ObjectFit(id=f"o{k}", mesh="m", pixels=n, support=1.0, residual_m=0.001)

    objects = [judged(k, n) for k, n in enumerate(pixels)]
    empty = np.zeros((2, 2))
    return SceneFit(objects=objects, foreground_px=50_000, unexplained=0.09, problems=[],
                    mask=empty, foreground=empty > 0, largest_unexplained_px=largest)  # fmt: skip


def test_a_region_the_size_of_a_part_is_a_loose_part():
    smallest = 2400
    at = int(LOOSE_PART_SHARE * smallest)
    assert _fit(at - 1, smallest, 10_000).loose_part() is None
    found = _fit(6468, smallest, 10_000, None).loose_part()  # a hidden object is not judged
    assert found is not None and "6468 px" in found and f"shows {smallest} px" in found
    assert _fit(at, smallest).loose_part() is not None


def test_without_a_judged_object_nothing_is_called_loose():
    assert _fit(10_000, None, None).loose_part() is None
    assert _fit(10_000).loose_part() is None


def _at(support: float | None, residual_m: float | None = None) -> ObjectFit:
    """An object's fit at one pose; `support` None: hidden there."""
    hidden = support is None
    return ObjectFit(id="o", mesh="m", pixels=0 if hidden else 500, support=support,
                     residual_m=None if hidden else residual_m)  # fmt: skip


GOOD = _at(0.99, 0.002)  # what a right reading leaves (docs/executor.md, the referee)
REFUTED = _at(0.53, 0.24)  # a cube read 40 mm into the table's space behind a tower
HIDDEN = _at(None)


def test_a_belief_the_image_shows_beats_a_look_it_refutes_or_cannot_see():
    assert prefers(GOOD, REFUTED) and prefers(GOOD, HIDDEN)
    assert prefers(GOOD, _at(0.99, 0.002 + PREFER_MARGIN_M + 0.001))
    assert not prefers(GOOD, _at(0.99, 0.002 + PREFER_MARGIN_M - 0.001))  # as good: the look
    assert not prefers(_at(0.3, 0.002), HIDDEN)  # the image does not show the belief either
    assert not prefers(_at(0.99, RESIDUAL_MAX_M + 0.001), HIDDEN)


def test_a_hidden_belief_beats_only_a_look_the_image_refutes():
    assert prefers(HIDDEN, REFUTED)
    assert prefers(HIDDEN, _at(SUPPORT_MIN - 0.01, 0.002))
    assert prefers(HIDDEN, _at(0.99, RESIDUAL_MAX_M + 0.001))
    assert not prefers(HIDDEN, GOOD)  # a move the image shows
    assert not prefers(HIDDEN, HIDDEN)  # nothing to judge by: the look


_fits = st.builds(
    _at,
    st.one_of(st.none(), st.floats(0.0, 1.0)),
    st.floats(0.0, 0.5),
)


@given(_fits, _fits)
def test_a_look_that_fits_where_it_puts_the_object_is_kept_unless_the_belief_fits_clearly_better(
    there, here
):
    """Whatever the belief's fit, a look the image supports (support and residual within the
    bounds) loses only to a belief the image shows and fits by over `PREFER_MARGIN_M` better."""
    look_fits = here.support is not None and here.support >= SUPPORT_MIN
    look_fits = look_fits and here.residual_m is not None and here.residual_m <= RESIDUAL_MAX_M
    if look_fits and prefers(there, here):
        assert there.support is not None and there.support >= SUPPORT_MIN
        assert there.residual_m is not None
        assert there.residual_m + PREFER_MARGIN_M < here.residual_m
