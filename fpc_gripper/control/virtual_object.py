"""A virtual object in the gripper: every finger's contact with it at a measured pressure."""

from dataclasses import dataclass
import math

import numpy as np

from fpc_gripper.grasp.finger import finger_grasps
from fpc_gripper.grasp.grasp import GraspSettings, simulate_grasp
from fpc_gripper.model.contact import ContactSettings
from fpc_gripper.model.pipeline import ModelSettings
from fpc_gripper.model.validation import real_number

__all__ = ['FingerContact', 'VirtualObject']


@dataclass(frozen=True)
class FingerContact:
    """
    Contact state of one finger with the object.

    Attributes
    ----------
    pressure : float
        Gauge pressure [Pa].
    normal_force : float
        Sum of the normal forces of the object on the finger [N].
    force : tuple of float
        Resultant (F_X, F_Z) of the contact forces on the finger, finger frame [N]: what
        ``finger_<i>/tip_force`` carries.
    torque : float
        Their moment about the fingertip (midplane), about +Y [N m]: with `force` at the
        tip, a wrench equivalent to the contact loads.
    in_contact : bool
    arc : tuple of float or None
        (start, end) reference arc length of the touching points [m].
    tip : tuple of float
        Midplane tip (X, Z) of the finger in contact [m].

    """

    pressure: float
    normal_force: float
    force: tuple
    torque: float
    in_contact: bool
    arc: tuple
    tip: tuple

    @property
    def tip_force(self):
        """(F_X, F_Z) [N] to publish."""
        return self.force


class VirtualObject:
    """
    A rigid object held in the palm, felt by every finger through the contact model.

    Finger i touches the object's section in its own plane (`obj.section`), solved by
    `FingerGrasp` (frictionless contact on the finger pipeline's contact model): the
    same model the controller's inverse uses. Friction enters only the holding force,
    which needs a loading path (`holding_force`).

    Parameters
    ----------
    obj : CoaxialCylinder, Sphere, CrossCylinder or Box
    config : GripperConfig
    settings : ModelSettings
    penalty : float
        0: a rigid object; > 0: a compliant surface of that stiffness [N/m].

    """

    def __init__(self, obj, config, settings=ModelSettings(), penalty=0.0):
        penalty = real_number('penalty', penalty, '[N/m]')
        if penalty < 0.0:
            raise ValueError(f'`penalty` must be >= 0 [N/m], got {penalty}')
        self.obj = obj
        self.config = config
        self.settings = settings
        self.fingers = finger_grasps(obj, config, settings, ContactSettings(penalty=penalty))

    @property
    def touch_pressure(self):
        """Largest pressure at which any free finger touches the object [Pa]."""
        return max(f.touch_pressure for f in self.fingers)

    def contact(self, index, pressure):
        """
        Contact of finger `index` at a gauge pressure [Pa].

        Returns
        -------
        FingerContact

        Raises
        ------
        RuntimeError
            If the contact model does not converge.

        """
        pressure = real_number('pressure', pressure, '[Pa]')
        state = self.fingers[index].state(max(pressure, 0.0))
        on_finger = -state.total_force.sum(axis=0)
        mine = state.in_contact
        arm = state.position[mine] - state.tip
        forces = state.force[mine]
        torque = float(np.sum(arm[:, 1] * forces[:, 0] - arm[:, 0] * forces[:, 1]))
        return FingerContact(pressure=pressure, normal_force=state.normal_force_total,
                             force=(float(on_finger[0]), float(on_finger[1])), torque=torque,
                             in_contact=bool(mine.any()), arc=state.contact_arc(),
                             tip=(float(state.tip[0]), float(state.tip[1])))

    def holding_force(self, pressure, mu, settings=None):
        """
        Largest pull-out force along the palm axis of a grasp at `pressure` [Pa], with mu.

        The grasp is that of `fpc_gripper.grasp.simulate_grasp`: opened, the object placed,
        released to `pressure` with friction mu, then pulled.

        Returns
        -------
        GraspPoint

        """
        settings = GraspSettings(model=self.settings) if settings is None else settings
        pressure = min(max(real_number('pressure', pressure, '[Pa]'), 0.0),
                       self.config.max_pressure)
        return simulate_grasp(self.config, self.obj, [pressure], mu, settings).points[0]

    def total_normal_force(self, pressures):
        """Sum over the fingers of their normal forces [N] at their pressures [Pa]."""
        return float(math.fsum(self.contact(i, p).normal_force
                               for i, p in enumerate(pressures)))
