"""A virtual cylinder on the palm axis that pushes on the fingertips it would be penetrated by."""

from dataclasses import dataclass
import enum
import math

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.optimize import brentq

__all__ = ['Contact', 'ContactMethod', 'VirtualCylinder']

#: Pressure spacing of the contact-force table [Pa].
DEFAULT_TABLE_STEP = 10.0e3
#: Largest contact force looked for [N]; beyond it the finger model leaves its valid range.
DEFAULT_MAX_FORCE = 5.0


class ContactMethod(str, enum.Enum):
    """How the contact force is found."""

    EXACT = 'exact'
    PENALTY = 'penalty'


@dataclass(frozen=True)
class Contact:
    """
    Contact state of one fingertip.

    Attributes
    ----------
    pressure : float
        Gauge pressure [Pa].
    force : float
        p0, the contact force on the tip along the finger's +Z [N] (>= 0).
    in_contact : bool
    free_rho : float
        Tip radius the unloaded finger would have [m].
    rho : float
        Tip radius with the contact force [m].
    penetration : float
        D/2 - free_rho [m]: how deep the free finger would reach into the object.

    """

    pressure: float
    force: float
    in_contact: bool
    free_rho: float
    rho: float
    penetration: float

    @property
    def tip_force(self):
        """(f0, p0) [N] to publish: friction is ignored, so f0 = 0."""
        return (0.0, self.force)


class VirtualCylinder:
    """
    A rigid (or compliant) cylinder of diameter D on the palm axis.

    A fingertip whose unloaded radius rho_free(P) would be below D/2 touches it
    and receives a force p0 > 0 along its +Z (radially outwards, the contact
    normal of a cylinder on the axis). Friction is ignored (f0 = 0), and only the
    tip touches: for the paper's finger, which curls less than a half turn, the
    tip is the innermost point of the midplane.

    ``method='exact'`` finds the p0 for which the loaded model puts the tip exactly
    on the surface, rho(P, p0) = D/2 (a rigid object). ``method='penalty'`` models
    a compliant surface of stiffness k: p0 = k (D/2 - rho(P, p0)), and the
    equilibrium (not an explicit penalty step, which would oscillate) is found.
    Both are roots in p0 of the increasing function
    h(p0) = rho(P, p0) - D/2 + p0 / k (1/k = 0 for exact).

    Parameters
    ----------
    diameter : float
        D [m], > 0.
    model : InverseModel
        Finger model (gives rho and the exact solves).
    method : {'exact', 'penalty'}
    stiffness : float
        k [N/m] for the penalty method.
    table_step : float
        The force is tabulated against pressure at this spacing [Pa] from 0 to the
        pressure at which the free tip just touches, and interpolated (PCHIP);
        `exact_force` skips the table.
    max_force : float
        Largest force looked for [N]; the force saturates there.

    """

    def __init__(self, diameter, model, method='exact', stiffness=200.0,
                 table_step=DEFAULT_TABLE_STEP, max_force=DEFAULT_MAX_FORCE):
        self.diameter = float(diameter)
        if not (math.isfinite(self.diameter) and self.diameter > 0.0):
            raise ValueError(f'`diameter` must be finite and > 0 [m], got {diameter!r}')
        self.method = ContactMethod(method)
        self.stiffness = float(stiffness)
        if self.method is ContactMethod.PENALTY and not (
                math.isfinite(self.stiffness) and self.stiffness > 0.0):
            raise ValueError(f'`stiffness` must be finite and > 0 [N/m], got {stiffness!r}')
        self.table_step = float(table_step)
        if not (math.isfinite(self.table_step) and self.table_step > 0.0):
            raise ValueError(f'`table_step` must be finite and > 0 [Pa], got {table_step!r}')
        self.max_force = float(max_force)
        if not (math.isfinite(self.max_force) and self.max_force > 0.0):
            raise ValueError(f'`max_force` must be finite and > 0 [N], got {max_force!r}')
        self.model = model
        self._compliance = 0.0 if self.method is ContactMethod.EXACT else 1.0 / self.stiffness
        self._table = None
        self.touch_pressure = self._touch_pressure()

    @property
    def radius(self):
        """D/2 [m]."""
        return 0.5 * self.diameter

    def _touch_pressure(self):
        """Largest pressure at which the free tip reaches the surface [Pa] (0: never)."""
        low, high = self.model.rho_range
        if self.radius <= low:
            return 0.0
        if self.radius >= high:
            return self.model.max_pressure
        return self.model.pressure_for_rho(self.radius).x

    def _h(self, pressure, force):
        return self.model.rho(pressure, (0.0, force)) - self.radius + self._compliance * force

    def exact_force(self, pressure):
        """
        Contact force [N] at a gauge pressure [Pa] by a root find on the exact model.

        Raises
        ------
        RuntimeError
            If the finger model does not converge.

        """
        pressure = float(pressure)
        free = self.model.rho(pressure)
        if free >= self.radius:
            return 0.0
        lin = self.model.linearise(pressure, (0.0, 0.0))
        compliance = lin.drho_dp0 + self._compliance
        high = min(self.max_force, 1.5 * (self.radius - free) / max(compliance, 1e-6) + 1e-3)
        while self._h(pressure, high) < 0.0:
            if high >= self.max_force:
                return self.max_force
            high = min(self.max_force, 2.0 * high)
        return float(brentq(lambda f: self._h(pressure, f), 0.0, high, xtol=1e-9))

    def _build_table(self):
        top = self.touch_pressure
        if top <= 0.0:
            self._table = None
            return
        n = max(3, int(math.ceil(top / self.table_step)) + 1)
        pressures = np.linspace(0.0, top, n)
        # The force falls to 0 exactly at the touch pressure, unless the object is so
        # wide that the tip touches it even at max_pressure.
        forces = [self.exact_force(p) for p in pressures[:-1]]
        forces.append(0.0 if top < self.model.max_pressure else self.exact_force(top))
        self._table = PchipInterpolator(pressures, np.array(forces))

    def force(self, pressure):
        """
        Contact force [N] at a gauge pressure [Pa], from the table (built on first use).

        With the default step the table is within 1e-4 N of `exact_force` on the
        paper's finger; pressures beyond its ends are clipped to them.
        """
        pressure = float(pressure)
        if not math.isfinite(pressure):
            raise ValueError(f'`pressure` must be finite [Pa], got {pressure}')
        if pressure >= self.touch_pressure and self.touch_pressure < self.model.max_pressure:
            return 0.0
        if self._table is None:
            self._build_table()
            if self._table is None:
                return 0.0
        pressure = min(max(pressure, 0.0), self.touch_pressure)
        return max(float(self._table(pressure)), 0.0)

    def contact(self, pressure):
        """
        Contact state of a tip at a gauge pressure [Pa].

        Returns
        -------
        Contact

        """
        pressure = float(pressure)
        force = self.force(pressure)
        free = self.model.rho_map(pressure)
        rho = free if force <= 0.0 else self.radius - self._compliance * force
        return Contact(pressure=pressure, force=force, in_contact=force > 0.0, free_rho=free,
                       rho=rho, penetration=self.radius - free)
