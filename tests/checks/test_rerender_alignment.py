"""`image.perceive_rerender` may shift a re-render as a whole by what the calibration error can
move the image by: `best_shift` finds that shift, scored on the observed objects' pixels."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from checks.suites.perceive import _shift, best_shift


def _by_definition(same: np.ndarray, ref: np.ndarray, k: int) -> tuple[int, int]:
    """Every shift of the whole image, compared with the reference everywhere."""
    best, shift = -1, (0, 0)
    for dy in range(-k, k + 1):
        for dx in range(-k, k + 1):
            score = int(((_shift(same, dy, dx, -1) == ref) & (ref >= 0)).sum())
            if score > best or (score == best and abs(dy) + abs(dx) < sum(map(abs, shift))):
                best, shift = score, (dy, dx)
    return shift


@settings(max_examples=150, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    h=st.integers(9, 16),  # larger than any shift (the images are hundreds of pixels)
    w=st.integers(9, 16),
    k=st.integers(0, 4),
    labels=st.integers(1, 3),
)
def test_the_shift_is_the_one_the_whole_image_comparison_picks(seed, h, w, k, labels):
    rng = np.random.default_rng(seed)
    same = rng.integers(-2, labels, (h, w))
    ref = rng.integers(-1, labels, (h, w))
    if rng.random() < 0.5:  # a reference that is the re-render moved, with a few pixels changed
        ref = _shift(np.where(same >= 0, same, -1), *rng.integers(-k, k + 1, 2), -1)
        ref[rng.random((h, w)) < 0.1] = -1
    assert best_shift(same, ref, k) == _by_definition(same, ref, k)


def test_a_re_render_drawn_two_pixels_off_is_moved_back():
    ref = np.full((40, 50), -1)
    ref[10:20, 5:15] = 0
    ref[22:35, 30:44] = 1
    drawn = _shift(ref, -2, 1, -1)  # the re-render, two rows up and one column right
    assert best_shift(drawn, ref, 3) == (2, -1)
    assert best_shift(drawn, ref, 1) == (1, -1)  # as far as it may go
