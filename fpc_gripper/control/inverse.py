"""Model-inverse feedforward: the gauge pressure that puts a fingertip at a target radius."""

from collections import OrderedDict
from dataclasses import dataclass
import enum
import math

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.optimize import brentq

from fpc_gripper.model.pipeline import finger_model
from fpc_gripper.model.pipeline import ModelSettings
from fpc_gripper.model.validation import real_number

__all__ = ['InverseModel', 'InverseResult', 'InverseStatus', 'Linearisation']

#: Pressure grid spacing of the monotone map built at start [Pa].
DEFAULT_GRID_STEP = 10.0e3
#: Absolute pressure tolerance of the root finds [Pa]; far below the regulator's resolution.
DEFAULT_XTOL = 1.0e-3
#: Finite-difference steps of the sensitivities: pressure [Pa] and tip force [N].
_H_PRESSURE = 200.0
_H_FORCE = 2.0e-3
_CACHE_SIZE = 256
#: Largest gap between the target and the achieved radius still called exact [m].
_REACHED = 1.0e-9
#: A residual this small is a root: the solves agree to round-off, some 1e-15 m [m].
_ROUND_OFF = 1.0e-13


class InverseStatus(enum.IntEnum):
    """Outcome of an inverse solve; only SUCCESS has success=True."""

    SUCCESS = 0
    BELOW_RANGE = 1
    ABOVE_RANGE = 2
    SOLVER_FAILED = 3


_MESSAGES = {
    InverseStatus.SUCCESS: 'target radius reached to {xtol:.0e} Pa in pressure',
    InverseStatus.BELOW_RANGE: 'target radius {target:.5f} m is below the radius at 0 Pa '
                               '({low:.5f} m): returning 0 Pa',
    InverseStatus.ABOVE_RANGE: 'target radius {target:.5f} m is above the radius at max_pressure '
                               '({high:.5f} m): returning max_pressure',
    InverseStatus.SOLVER_FAILED: 'the finger model did not converge at {pressure:.1f} Pa: {why}',
}


@dataclass(frozen=True)
class InverseResult:
    """
    Result of an inverse solve, in the manner of scipy's OptimizeResult.

    Attributes
    ----------
    x : float
        Gauge pressure [Pa], within [0, max_pressure].
    success : bool
    status : InverseStatus
    message : str
    nfev : int
        CCM solves spent.
    target : float
        Requested tip radius [m].
    rho : float
        Tip radius the model gives at `x` [m] (nan if the solver failed).
    tip_force : tuple of float
        (f0, p0) used [N].

    """

    x: float
    success: bool
    status: InverseStatus
    message: str
    nfev: int
    target: float
    rho: float
    tip_force: tuple


@dataclass(frozen=True)
class Linearisation:
    """
    First-order model of rho(P, f0, p0) around a reference state.

    Attributes
    ----------
    pressure : float
        Reference gauge pressure [Pa].
    tip_force : tuple of float
        Reference (f0, p0) [N].
    rho : float
        Tip radius at the reference [m].
    drho_dp : float
        d rho / d P [m/Pa].
    drho_df0, drho_dp0 : float
        d rho / d f0 and d rho / d p0 [m/N].

    """

    pressure: float
    tip_force: tuple
    rho: float
    drho_dp: float
    drho_df0: float
    drho_dp0: float

    def __call__(self, pressure, tip_force):
        """Evaluate the linear model at (pressure [Pa], (f0, p0) [N]) -> rho [m]."""
        return (self.rho + self.drho_dp * (pressure - self.pressure)
                + self.drho_df0 * (tip_force[0] - self.tip_force[0])
                + self.drho_dp0 * (tip_force[1] - self.tip_force[1]))

    @property
    def dp_dforce(self):
        """Return dP/dp0 at constant rho [Pa/N] (negative: more grip needs less pressure)."""
        return -self.drho_dp0 / self.drho_dp


class _SolveFailed(Exception):
    def __init__(self, pressure, result):
        super().__init__(result.message)
        self.pressure = pressure
        self.result = result


def _force(tip_force):
    if np.shape(tip_force) != (2,):
        raise ValueError(f'`tip_force` must be (f0, p0) [N], got {tip_force!r}')
    return (real_number('tip_force[0]', tip_force[0], '[N]'),
            real_number('tip_force[1]', tip_force[1], '[N]'))


def _snap(value, step):
    """Round to a multiple of `step`, keeping non-zero values off 0 (0.0, never -0.0)."""
    if value == 0.0:
        return 0.0
    return math.copysign(max(1, round(abs(value) / step)) * step, value)


class InverseModel:
    """
    Inverse of the finger model: pressure for a tip radius under a tip load, estimates.

    The grasp (a contact force on an object) has its own inverse,
    `fpc_gripper.grasp.FingerGrasp`, on the contact model.

    The finger is the one of the finger pipeline (`finger_model(design, settings)`),
    the model `model_node` publishes with the same settings. At construction the
    unloaded finger is solved on a pressure grid over [0, max_pressure]; the tip
    radius rho = palm_radius + Z_tip must be strictly increasing on it (the region
    where the gripper is controlled), otherwise ValueError is raised. Interpolating
    that monotone map (PCHIP) gives a first guess that one bracketed Brent root find
    on the exact model then polishes.

    Parameters
    ----------
    design : ActuatorDesign
        The finger.
    palm_radius : float
        Palm centre to the clamp edge [m].
    max_pressure : float
        Largest gauge pressure the inverse may return [Pa].
    settings : ModelSettings
        How the finger is modelled (default: the node's defaults).
    grid_step : float
        Spacing of the map [Pa].
    xtol : float
        Pressure tolerance of the root finds [Pa].

    Notes
    -----
    Every answer is a function of the call's arguments alone. Each solve is
    warm-started from the grid state nearest in pressure, and a warm start changes
    only the iteration count (the solver converges to 1e-9 in its scaled unknowns,
    some 1e-15 m in radius, far below what `xtol` resolves); so the residual of a
    root find is a fixed function of pressure and a bracket end evaluated twice has
    the same sign. Caches are keyed by the whole input.

    """

    def __init__(self, design, palm_radius, max_pressure, settings=ModelSettings(),
                 grid_step=DEFAULT_GRID_STEP, xtol=DEFAULT_XTOL):
        self.palm_radius = real_number('palm_radius', palm_radius, '[m]')
        self.max_pressure = real_number('max_pressure', max_pressure, '[Pa]')
        grid_step = real_number('grid_step', grid_step, '[Pa]')
        self.xtol = real_number('xtol', xtol, '[Pa]')
        if self.palm_radius <= 0.0:
            raise ValueError(f'`palm_radius` must be > 0 [m], got {self.palm_radius}')
        if self.max_pressure <= 0.0:
            raise ValueError(f'`max_pressure` must be > 0 [Pa], got {self.max_pressure}')
        if grid_step <= 0.0:
            raise ValueError(f'`grid_step` must be > 0 [Pa], got {grid_step}')
        if self.xtol <= 0.0:
            raise ValueError(f'`xtol` must be > 0 [Pa], got {self.xtol}')
        self.settings = settings
        self.solver = finger_model(design, settings)
        self.design = design
        self.nfev = 0
        n = max(4, int(math.ceil(self.max_pressure / grid_step)) + 1)
        self.grid_pressure = np.linspace(0.0, self.max_pressure, n)
        self._grid_results = []
        previous = None
        for p in self.grid_pressure:
            r = self.solver.solve(float(p), initial=previous, outputs='tip')
            self.nfev += 1
            if not r.success:
                raise ValueError(f'`design` cannot be solved unloaded at {p:.0f} Pa: {r.message}')
            self._grid_results.append(r)
            previous = r
        self.grid_rho = np.array([self.palm_radius + r.tip[1] for r in self._grid_results])
        steps = np.diff(self.grid_rho)
        if not np.all(steps > 0.0):
            bad = float(self.grid_pressure[1:][np.argmin(steps)])
            raise ValueError('`max_pressure` must lie in the region where the tip radius '
                             f'increases with pressure; it stops increasing near {bad:.0f} Pa')
        self._forward = PchipInterpolator(self.grid_pressure, self.grid_rho)
        self._slope = self._forward.derivative()
        self._backward = PchipInterpolator(self.grid_rho, self.grid_pressure)
        self._cache = OrderedDict()
        self._linearisations = OrderedDict()

    # -- forward model ------------------------------------------------------------------

    @property
    def rho_range(self):
        """Unloaded tip radii at 0 Pa and max_pressure [m]."""
        return float(self.grid_rho[0]), float(self.grid_rho[-1])

    def _initial(self, pressure):
        """Return the grid state nearest in pressure: a warm start set by `pressure` alone."""
        index = int(np.argmin(np.abs(self.grid_pressure - pressure)))
        return self._grid_results[index]

    def solve(self, pressure, tip_force=(0.0, 0.0)):
        """
        Equilibrium of the finger at a gauge pressure and tip load.

        Parameters
        ----------
        pressure : float
            Gauge pressure [Pa], >= 0.
        tip_force : (float, float)
            (f0, p0) along the finger's X and Z [N].

        Returns
        -------
        Result
            The finger pipeline's result, its outputs to the tip (`model_choice` for an
            adaptive model).

        """
        pressure = real_number('pressure', pressure, '[Pa]')
        tip_force = _force(tip_force)
        result = self.solver.solve(pressure, tip_force=tip_force,
                                   initial=self._initial(pressure), outputs='tip')
        self.nfev += 1
        return result

    def rho(self, pressure, tip_force=(0.0, 0.0)):
        """
        Exact tip radius rho = palm_radius + Z_tip [m] at a pressure [Pa] and load [N].

        Raises
        ------
        RuntimeError
            If the solver does not converge.

        """
        result = self.solve(pressure, tip_force)
        if not result.success:
            raise RuntimeError(f'CCM solve failed at {pressure} Pa, tip force {tip_force} N: '
                               f'{result.message}')
        return self.palm_radius + float(result.tip[1])

    def rho_map(self, pressure):
        """Unloaded tip radius from the interpolated map [m] (about 1e-5 m accurate)."""
        return float(self._forward(np.clip(pressure, 0.0, self.max_pressure)))

    def map_pressure(self, rho):
        """Pressure of the unloaded map for a tip radius [m], clipped to its range [Pa]."""
        low, high = self.rho_range
        return float(self._backward(min(max(rho, low), high)))

    def slope(self, pressure):
        """Return d rho / d P of the unloaded map [m/Pa]."""
        return float(self._slope(np.clip(pressure, 0.0, self.max_pressure)))

    def linearise(self, pressure, tip_force=(0.0, 0.0)):
        """
        Linearisation of rho(P, f0, p0) by forward differences of exact solves.

        The differences are taken on the discretisation that models the reference
        state, so that a change of model between neighbouring scenes (which the
        adaptive model may make) never enters a slope.

        Parameters
        ----------
        pressure : float
            Gauge pressure [Pa].
        tip_force : (float, float)
            (f0, p0) [N].

        Returns
        -------
        Linearisation
            drho_df0 is computed only when f0 != 0 (else 0: no X load is modelled).

        Raises
        ------
        RuntimeError
            If a solve does not converge.

        """
        pressure = real_number('pressure', pressure, '[Pa]')
        f0, p0 = _force(tip_force)
        reference = self.solve(pressure, (f0, p0))
        if not reference.success:
            raise RuntimeError(f'finger model failed at {pressure} Pa, tip force ({f0}, {p0}) '
                               f'N: {reference.message}')
        # The finite differences stay on the reference's rung and N, wherever the model
        # would choose another.
        choice = reference.model_choice
        fixed = self.solver if choice is None else self.solver.solver_for(choice.rung,
                                                                          choice.n_segments)

        def rho(p, force):
            result = fixed.solve(p, force, initial=reference, outputs='tip')
            self.nfev += 1
            if not result.success:
                raise RuntimeError(f'finger model failed at {p} Pa, tip force {force} N: '
                                   f'{result.message}')
            return self.palm_radius + float(result.tip[1])

        rho0 = self.palm_radius + float(reference.tip[1])
        h = _H_PRESSURE if pressure + _H_PRESSURE <= self.max_pressure else -_H_PRESSURE
        drho_dp = (rho(pressure + h, (f0, p0)) - rho0) / h
        drho_dp0 = (rho(pressure, (f0, p0 + _H_FORCE)) - rho0) / _H_FORCE
        drho_df0 = 0.0
        if f0 != 0.0:
            drho_df0 = (rho(pressure, (f0 + _H_FORCE, p0)) - rho0) / _H_FORCE
        return Linearisation(pressure, (f0, p0), rho0, drho_dp, drho_df0, drho_dp0)

    def estimate(self, pressure, tip_force=(0.0, 0.0), pressure_window=4.0e3,
                 force_window=0.03):
        """
        Cheap tip radius for a measured state: a linearisation about the nearest cell centre.

        The reference is the measured state rounded to a grid of `pressure_window` [Pa]
        and `force_window` [N] (clipped to [0, max_pressure]; a non-zero load component
        never rounds to 0, since an unloaded finger may be modelled more coarsely), so
        the answer is a function of the arguments alone; linearisations are cached per
        reference. The error is second order, below 2e-5 m for the default windows on
        the paper's finger.

        Returns
        -------
        rho : float
            [m].
        linearisation : Linearisation
            The reference used.

        Raises
        ------
        RuntimeError
            If a solve at the reference does not converge.

        """
        pressure = real_number('pressure', pressure, '[Pa]')
        f0, p0 = _force(tip_force)
        reference = (min(max(round(pressure / pressure_window) * pressure_window, 0.0),
                         self.max_pressure),
                     _snap(f0, force_window), _snap(p0, force_window))
        lin = self._linearisations.get(reference)
        if lin is None:
            lin = self.linearise(reference[0], reference[1:])
            self._linearisations[reference] = lin
            if len(self._linearisations) > _CACHE_SIZE:
                self._linearisations.popitem(last=False)
        return lin(pressure, (f0, p0)), lin

    # -- inverse ------------------------------------------------------------------------

    def _residual(self, tip_force, target):
        def residual(pressure):
            result = self.solve(pressure, tip_force)
            if not result.success:
                raise _SolveFailed(pressure, result)
            return self.palm_radius + float(result.tip[1]) - target
        return residual

    def pressure_for_rho(self, rho, tip_force=(0.0, 0.0)):
        """
        Gauge pressure that puts the tip at radius `rho` under a tip load.

        Parameters
        ----------
        rho : float
            Target tip radius palm_radius + Z_tip [m].
        tip_force : (float, float)
            (f0, p0) [N], e.g. the current tip-force estimate.

        Returns
        -------
        InverseResult
            `x` solves rho(x, tip_force) = rho to `xtol` [Pa]. A target out of
            reach returns the nearest end (0 or max_pressure) with status
            BELOW_RANGE or ABOVE_RANGE.

        """
        target = real_number('rho', rho, '[m]')
        tip_force = _force(tip_force)
        key = (target, tip_force)
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        result = self._pressure_for_rho(target, tip_force)
        self._cache[key] = result
        if len(self._cache) > _CACHE_SIZE:
            self._cache.popitem(last=False)
        return result

    def _pressure_for_rho(self, target, tip_force):
        start = self.nfev
        f = self._residual(tip_force, target)
        p_max = self.max_pressure
        low_rho, high_rho = self.rho_range
        guess = float(self._backward(np.clip(target, low_rho, high_rho)))
        try:
            f_guess = f(guess)
            if tip_force != (0.0, 0.0):
                # One Newton step with the unloaded slope shifts the guess for the load.
                slope = max(self.slope(guess), 1e-9)
                moved = float(np.clip(guess - f_guess / slope, 0.0, p_max))
                width = max(2.0e3, 0.25 * abs(moved - guess))
                guess, f_guess = moved, f(moved)
            else:
                width = 2.0e3
            if abs(f_guess) <= _ROUND_OFF:
                return self._result(guess, InverseStatus.SUCCESS, start, target, tip_force,
                                    target)
            # Expand a bracket on the side the residual points to.
            direction = -1.0 if f_guess > 0.0 else 1.0
            a, fa = guess, f_guess
            while True:
                b = float(np.clip(a + direction * width, 0.0, p_max))
                fb = f(b)
                if abs(fb) <= _ROUND_OFF or (fb > 0.0) != (fa > 0.0):
                    break
                if b in (0.0, p_max):
                    status = (InverseStatus.BELOW_RANGE if b == 0.0
                              else InverseStatus.ABOVE_RANGE)
                    return self._result(b, status, start, target, tip_force, target + fb)
                a, fa = b, fb
                width *= 4.0
            if abs(fb) <= _ROUND_OFF:
                root = b
            else:
                lo, hi = sorted((a, b))
                root = min(max(brentq(f, lo, hi, xtol=self.xtol, rtol=4.0 * np.finfo(float).eps),
                               lo), hi)
            achieved = target + f(root)
        except _SolveFailed as failure:
            return self._failed(guess, start, target, tip_force, failure.pressure,
                                failure.result.message)
        except (ValueError, RuntimeError, ArithmeticError) as exc:
            return self._failed(guess, start, target, tip_force, guess,
                                f'root find raised {type(exc).__name__}: {exc}')
        return self._result(root, InverseStatus.SUCCESS, start, target, tip_force, achieved)

    def _failed(self, guess, start, target, tip_force, pressure, why):
        return InverseResult(
            x=float(np.clip(guess, 0.0, self.max_pressure)), success=False,
            status=InverseStatus.SOLVER_FAILED,
            message=_MESSAGES[InverseStatus.SOLVER_FAILED].format(pressure=pressure, why=why),
            nfev=self.nfev - start, target=target, rho=math.nan, tip_force=tip_force)

    def _result(self, pressure, status, start, target, tip_force, achieved):
        low, high = self.rho_range
        message = _MESSAGES[status].format(xtol=self.xtol, target=target, low=low, high=high,
                                           pressure=pressure, why='')
        if status is InverseStatus.SUCCESS and abs(achieved - target) > _REACHED:
            # An adaptive model may change discretisation right at the root: the radius
            # then jumps there by at most the model tolerance.
            message += (f'; the model changes discretisation there, so the radius is '
                        f'{achieved - target:+.2e} m off the target')
        return InverseResult(x=min(max(float(pressure), 0.0), self.max_pressure),
                             success=status is InverseStatus.SUCCESS,
                             status=status, message=message, nfev=self.nfev - start,
                             target=target, rho=float(achieved), tip_force=tip_force)
