"""The optional weld assist: a physics aid, not something the robot knows (off by default).

While the jaws are commanded fully closed and both pads touch the held object, the object is
welded to the gripper; the weld lets go the moment the jaws are commanded open. It needs the
held object's body (to weld it), which is why it lives apart from the executor's decisions:
it never tells the executor anything. docs/executor.md measures both modes.
"""

from __future__ import annotations

from collections.abc import Mapping

import mujoco
import numpy as np

from contracts import se3
from sim import robot


class WeldAssist:
    """Welds the held object to the gripper base while it is gripped (see the module doc)."""

    def __init__(
        self, model: mujoco.MjModel, data: mujoco.MjData, index: robot.RobotIndex,
        bodies: Mapping[str, int],
    ) -> None:  # fmt: skip
        self.model, self.data, self.index = model, data, index
        self.bodies = dict(bodies)
        self._geoms = {
            oid: frozenset(np.flatnonzero(model.geom_bodyid == b).tolist())
            for oid, b in self.bodies.items()
        }
        self._pads = (np.array(sorted(index.left_pads)), np.array(sorted(index.right_pads)))
        self.held: str | None = None
        self.on = False
        self.engaged = False  # it welded at some point since `hold`

    def hold(self, oid: str | None) -> None:
        """The executor is about to grip `oid` (None: it let go)."""
        if oid != self.held:
            self.release()
        self.held = oid if oid in self.bodies else None
        if oid is not None:
            self.engaged = False  # counts from this grip; letting go keeps it for the outcome

    def update(self, grip_cmd: float) -> None:
        """Weld or release after a control tick, from the command and the pads' contacts."""
        if self.held is None:
            return
        closing = grip_cmd >= robot.GRIPPER_CLOSED - 1e-6
        want = closing and self._both_pads_touch(self._geoms[self.held])
        if want and not self.on:
            self._weld(self.bodies[self.held])
        elif self.on and not want:
            self.release()

    def release(self) -> None:
        eq = self.index.weld
        if eq >= 0:
            self.data.eq_active[eq] = 0
            self.model.eq_obj2id[eq] = 0
        self.on = False

    def _both_pads_touch(self, geoms: frozenset[int]) -> bool:
        d = self.data
        n = d.ncon
        if n == 0:
            return False
        g = d.contact.geom[:n]
        obj = np.isin(g, list(geoms))
        touch = []
        for pads in self._pads:
            side = np.isin(g, pads)
            touch.append(bool(np.any((obj[:, 0] & side[:, 1]) | (obj[:, 1] & side[:, 0]))))
        return all(touch)

    def _weld(self, body: int) -> None:
        m, d, eq = self.model, self.data, self.index.weld
        g = self.index.gripper_base
        T1 = se3.make(d.xmat[g].reshape(3, 3), d.xpos[g])
        T2 = se3.make(d.xmat[body].reshape(3, 3), d.xpos[body])
        rel = se3.inverse(T1) @ T2  # the object in the gripper's frame, kept while welded
        m.eq_obj2id[eq] = body
        data = m.eq_data[eq]
        data[:3] = 0.0  # anchor at the object's origin
        data[3:6] = rel[:3, 3]
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, rel[:3, :3].ravel())
        data[6:10] = quat
        data[10] = 1.0  # torque scale
        d.eq_active[eq] = 1
        self.on = True
        self.engaged = True
