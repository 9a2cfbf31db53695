"""Static stability of rigid parts: convex pieces, resting poses, separation, support, loads.

This is the judge's own geometry (`geometry`, re-exported): the plan checks and the trials'
scoring decide "collision-free, supported, stable" with exactly these functions and their
default tolerances, so a plan whose every state passes `collisions(...) == []` and
`unstable_objects(...) == {}` with the defaults passes those parts of the checks. (The checks
and the programs sharing a bug is the price; the trials in MuJoCo physics are the arbiter the
geometry is tested against.)

Exact polyhedral geometry, no simulation and no sampling, fast enough to call inside a
planner's loop. An object's geometry is a `Shape`: convex pieces (vertex arrays in its own
frame) whose union is the object, made from a watertight mesh by `Shape.from_mesh` or given
directly. Distances between pieces come from the separating-axis theorem: exact for
penetration and for the face-to-face contacts of resting parts. The table is the plane z = 0
("table"). Uniform density. Records are `{"id", "mesh", "pose"}` with `pose` =
`T_world_object` (4, 4) [m]; `shapes` maps mesh keys to `Shape`s.

Default tolerances (the checks and the scoring judge with them): interpenetration up to `TOUCHING`
counts as touching; a gap up to `RESTING_GAP` counts as resting on; a centre of mass (with its
load) may lie `COM_MARGIN` outside its support; a contact normal with |z| from `VERTICAL` is a
support. Perceived states (`perceive`'s output, which `relate` and `plan` receive online; their
checks give them exact scenes) are accepted with more slack: objects up to `PERCEIVED_OVERLAP` into
one another and up to `PERCEIVED_GAP` above what holds them up; read overlaps and contacts in them
with that slack, and hold what a plan makes to the defaults.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, TypeVar

import geometry
from geometry import DegenerateError, RestingPose, UnknownShape
from geometry.tolerances import TOLERANCES
from toolbox.errors import ToolboxError

__all__ = [
    "COM_MARGIN",
    "PERCEIVED_GAP",
    "PERCEIVED_OVERLAP",
    "RESTING_GAP",
    "TOUCHING",
    "VERTICAL",
    "RestingPose",
    "Shape",
    "collisions",
    "separation",
    "stable_poses",
    "supports",
    "unstable_objects",
]

TOUCHING = TOLERANCES.penetration  # [m] deepest interpenetration still counted as touching
RESTING_GAP = TOLERANCES.contact  # [m] largest gap still counted as resting on
COM_MARGIN = TOLERANCES.com_margin  # [m] a centre of mass this far outside its support is held
PERCEIVED_OVERLAP = TOLERANCES.perceived_penetration  # [m] … between perceived objects
PERCEIVED_GAP = TOLERANCES.perceived_contact  # [m] … under a perceived object
VERTICAL = TOLERANCES.vertical  # |normal z| from which a contact is a support

_F = TypeVar("_F", bound=Callable[..., Any])


def _toolbox_errors(fn: _F) -> _F:
    """`fn` raising `ToolboxError` for bad input (what the toolbox documents)."""

    @functools.wraps(fn)
    def wrapped(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (DegenerateError, UnknownShape) as e:
            raise ToolboxError(str(e)) from None

    return wrapped  # type: ignore[return-value]


class Shape(geometry.Shape):
    __doc__ = geometry.Shape.__doc__

    def __init__(self, pieces: Any, *, exact: bool = True) -> None:
        try:
            super().__init__(pieces, exact=exact)
        except DegenerateError as e:
            raise ToolboxError(str(e)) from None

    @staticmethod
    def from_pieces(pieces: Any) -> Shape:
        """A shape from convex vertex arrays (k, 3) [m] in the object frame."""
        import numpy as np

        return Shape([np.asarray(p, dtype=float).reshape(-1, 3) for p in pieces])

    @staticmethod
    def from_mesh(mesh: Any, *, tolerance: float = 1e-3) -> Shape:
        try:
            s = geometry.Shape.from_mesh(mesh, tolerance=tolerance)
        except DegenerateError as e:
            raise ToolboxError(str(e)) from None
        return Shape(s.pieces, exact=s.exact)


Shape.from_mesh.__doc__ = geometry.Shape.from_mesh.__doc__
collisions = _toolbox_errors(geometry.collisions)
separation = _toolbox_errors(geometry.separation)
stable_poses = _toolbox_errors(geometry.stable_poses)
supports = _toolbox_errors(geometry.supports)
unstable_objects = _toolbox_errors(geometry.unstable_objects)
