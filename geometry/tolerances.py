"""The one tolerance table of the oracle geometry: every comparison names its entry.

Each entry says what physical fact it stands for. Generators, settling, the plan checks, trial
scoring and the grasp model all read these, so a plan step that one of them accepts the others
accept too. (A domain's scoring tolerances — how close to its goal an object must end — are the
domain's own, in `domains/<domain>/tolerances.json`.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, kw_only=True)
class Tolerances:
    penetration: float = 0.001
    """[m] deepest interpenetration still counted as touching: MuJoCo's soft contacts let
    resting objects sink a fraction of a millimetre, and a placement this deep settles without
    shoving its neighbours (deeper ones were seen to shove packed pieces by millimetres)."""

    contact: float = 0.002
    """[m] largest gap still counted as resting on: the executor lets go 1 mm above a target
    and a released object drops that far; more is an object left hanging."""

    com_margin: float = 0.0005
    """[m] how far outside its support polygon a centre of mass (with its load) may lie: the
    contact patches are computed from hull vertices, which round a face's edge inwards."""

    vertical: float = 0.7
    """|normal z| above which a contact carries weight (a support) rather than touching
    sideways: 45° is where friction of wood on wood (μ ≈ 0.5–0.6) stops holding."""

    perceived_penetration: float = 0.003
    """[m] interpenetration allowed between *perceived* objects: each pose carries about a
    millimetre of error, so two touching objects may overlap by twice that."""

    perceived_contact: float = 0.004
    """[m] gap allowed under a *perceived* object resting on another or the table (as above)."""

    sweep_touch: float = 0.0005
    """[m] penetration of an object's vertical sweep (it rises straight up from the pick and
    comes straight down onto the place) still counted as touching, not hitting."""

    sweep_clearance: float = 0.002
    """[m] clearance an object's vertical sweep keeps from a neighbour wholly above it (one
    overhanging the pick or the place: the object passes under its edge): the held object
    sways by up to a millimetre in the hand and the arm tracks to about a millimetre
    (`grasp_margins`), so touching, as `sweep_touch` allows beside it, would knock it."""

    face_vertical: float = float(np.radians(3.0))
    """[rad] tilt within which a mesh face counts as vertical for the 2F-85's pads."""

    face_antiparallel: float = float(np.radians(4.0))
    """[rad] angle within which two faces count as opposite (a pad on each)."""

    yaw_only: float = float(np.radians(3.0))
    """[rad] tilt within which a pick → place change of orientation is a turn about the
    vertical (all a top-down grasp can do)."""

    grasp_margins: tuple[float, ...] = (0.006, 0.002)
    """[m] clearances tried between the gripper and the neighbours, larger preferred: 2 mm
    covers the arm's tracking error near objects (measured ≤ 1 mm) with room to spare."""


TOLERANCES = Tolerances()
