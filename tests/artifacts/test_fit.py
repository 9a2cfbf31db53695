"""`SceneFit.loose_part`: a region no perceived object explains, as large as a part, is named —
judged against the smallest object the fit could judge, not against the whole foreground."""

from __future__ import annotations

import numpy as np

from artifacts.fit import LOOSE_PART_SHARE, ObjectFit, SceneFit


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
