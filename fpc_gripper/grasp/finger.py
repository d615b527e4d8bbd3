"""One finger on a known object: its frictionless contact against pressure, and the inverse."""

from collections import OrderedDict

from scipy.optimize import brentq

from fpc_gripper.model.contact import ContactSettings, point_gaps, solve_contact
from fpc_gripper.model.pipeline import contact_model, ModelSettings
from fpc_gripper.model.validation import real_number

__all__ = ['FingerGrasp', 'finger_grasps']

#: Pressure tolerance of the root finds [Pa].
_XTOL = 1.0e-3
#: Pressure step of the force slope's central difference [Pa].
_H_PRESSURE = 500.0
_CACHE_SIZE = 256


class FingerGrasp:
    """
    A finger pressing on an object's section: normal force against pressure and back.

    Every answer comes from the contact model of the finger pipeline
    (`pipeline.contact_model`), frictionless (`contact.solve_contact`), a pure function of
    the pressure: the controller's inverse and the demo's virtual object both use it. The
    finger closes as the pressure falls, so the normal force falls with pressure from its
    value at 0 Pa to zero at the touch pressure, where the free finger meets the object.

    Parameters
    ----------
    design : ActuatorDesign
    section : tuple of obstacles
        The object in the finger frame (`Sphere.section(...)` etc.).
    max_pressure : float
        Largest pressure [Pa].
    settings : ModelSettings
    contact : ContactSettings

    """

    def __init__(self, design, section, max_pressure, settings=ModelSettings(),
                 contact=ContactSettings()):
        self.max_pressure = real_number('max_pressure', max_pressure, '[Pa]')
        if self.max_pressure <= 0.0:
            raise ValueError(f'`max_pressure` must be > 0 [Pa], got {self.max_pressure}')
        self.solver = self.solver_of(design, settings)
        self.section = tuple(section)
        self.contact = contact
        self._last = None
        self._states = OrderedDict()
        self.touch_pressure = self._touch_pressure()

    @staticmethod
    def solver_of(design, settings=ModelSettings()):
        """Return the contact model of a finger (`pipeline.contact_model`)."""
        return contact_model(design, settings)

    def state(self, pressure):
        """
        Frictionless contact at a gauge pressure [Pa] (clipped to [0, max_pressure]).

        Returns
        -------
        Result

        Raises
        ------
        RuntimeError
            If the contact solve fails.

        """
        pressure = min(max(real_number('pressure', pressure, '[Pa]'), 0.0), self.max_pressure)
        hit = self._states.get(pressure)
        if hit is not None:
            self._states.move_to_end(pressure)
            return hit
        result = solve_contact(self.solver, pressure, self.section, settings=self.contact,
                               initial=self._last)
        if not result.success:
            raise RuntimeError(f'contact solve failed at {pressure:.1f} Pa: {result.message}')
        self._last = result
        self._states[pressure] = result
        if len(self._states) > _CACHE_SIZE:
            self._states.popitem(last=False)
        return result

    def normal_force(self, pressure):
        """Sum of the normal forces of the object on the finger [N] at a pressure [Pa]."""
        return self.state(pressure).normal_force_total

    def _free_gap(self, pressure):
        """Smallest gap of the free finger from the object [m] (< 0: it would penetrate)."""
        free = self.solver.solve(pressure, outputs='tip')
        if not free.success:
            raise RuntimeError(f'free finger failed at {pressure:.1f} Pa: {free.message}')
        return float(point_gaps(self.solver, self.solver._pack(free.state), self.section,
                                self.contact).min())

    def _touch_pressure(self):
        """Pressure at which the free finger touches the object [Pa] (0: never, max: always)."""
        low, high = self._free_gap(0.0), self._free_gap(self.max_pressure)
        if low >= 0.0:
            return 0.0
        if high <= 0.0:
            return self.max_pressure
        return float(brentq(self._free_gap, 0.0, self.max_pressure, xtol=_XTOL))

    def pressure_for_force(self, force):
        """
        Pressure at which the finger presses on the object with a normal force [N].

        Returns
        -------
        pressure : float
            [Pa], in [0, touch_pressure].
        reachable : bool
            False when even 0 Pa presses less (then 0 Pa is returned).

        """
        force = real_number('force', force, '[N]')
        if force < 0.0:
            raise ValueError(f'`force` must be >= 0 [N], got {force}')
        top = self.touch_pressure
        if force == 0.0 or top == 0.0:
            return top, force == 0.0
        if self.normal_force(0.0) < force:
            return 0.0, False
        root = brentq(lambda p: self.normal_force(p) - force, 0.0, top, xtol=_XTOL)
        return float(root), True

    def slope(self, pressure):
        """d(normal force)/d(pressure) [N/Pa] by a central difference of exact solves."""
        pressure = min(max(real_number('pressure', pressure, '[Pa]'), _H_PRESSURE),
                       self.max_pressure - _H_PRESSURE)
        return (self.normal_force(pressure + _H_PRESSURE)
                - self.normal_force(pressure - _H_PRESSURE)) / (2.0 * _H_PRESSURE)


def finger_grasps(obj, config, settings=ModelSettings(), contact=ContactSettings()):
    """
    Return every finger's `FingerGrasp` of an object, where a gripper config mounts it.

    Parameters
    ----------
    obj : grasp object (`grasp.objects`)
    config : GripperConfig
        Its fingers' designs and mount angles, ``palm_radius`` and ``max_pressure``.
    settings : ModelSettings
    contact : ContactSettings

    Returns
    -------
    tuple of FingerGrasp
        In the config's finger order.

    """
    return tuple(FingerGrasp(f.design, obj.section(f.mount_angle, config.palm_radius),
                             config.max_pressure, settings, contact) for f in config.fingers)
