"""ROS-free closed loop for the control tests: control law + simulated regulator + cylinder."""

import math

import numpy as np

from fpc_gripper.control.controller import FingerMeasurement
from fpc_gripper.model import AdaptiveSolver
from fpc_gripper.model.pipeline import ModelSettings
from fpc_gripper.regulators.sim import SimulatedRegulator

PALM_RADIUS = 0.062


class FakeClock:
    """Injectable time [s]."""

    def __init__(self, start=100.0):
        self.now = float(start)

    def __call__(self):
        return self.now


class Loop:
    """
    Run a `GripperControlLaw` against `SimulatedRegulator` channels at a fixed period.

    The tip force fed back is ``tip_force(i, measured_pressure)`` (default none). Every
    step records time, commands, measured and true pressures and the law's output.
    """

    def __init__(self, law, period=0.02, tip_force=None, seed=3, **regulator):
        self.law = law
        self.period = period
        self.clock = FakeClock()
        n = len(law.models)
        self.regulator = SimulatedRegulator(n, clock=self.clock, seed=seed, **regulator)
        self.regulator.connect()
        self.tip_force = tip_force or (lambda i, p: (0.0, 0.0))
        self.freeze_feedback = False
        self.stuck_pressure = None
        self.log = []
        self._last = [None] * n

    def run(self, seconds):
        steps = int(round(seconds / self.period))
        out = None
        for _ in range(steps):
            self.clock.now += self.period
            measurements = []
            for i in range(len(self.law.models)):
                if self.freeze_feedback:
                    measurements.append(self._last[i])
                    continue
                p, _ = self.regulator.read_pressure(i)
                if self.stuck_pressure is not None:
                    p = self.stuck_pressure
                self._last[i] = FingerMeasurement(p, self.clock.now, self.tip_force(i, p))
                measurements.append(self._last[i])
            out = self.law.step(self.clock.now, measurements)
            if out.commands is not None:
                for i, c in enumerate(out.commands):
                    self.regulator.set_pressure(i, c)
            self.log.append({
                't': self.clock.now, 'out': out,
                'measured': [m.pressure for m in measurements],
                'true': [self.regulator.true_pressure(i) for i in range(len(self.law.models))],
                'tip_force': [m.tip_force for m in measurements],
            })
        return out

    def series(self, key, start=0):
        return np.array([row[key] for row in self.log[start:]], dtype=float)

    def commands(self, start=0):
        return np.array([row['out'].commands for row in self.log[start:]], dtype=float)

    def times(self, start=0):
        return np.array([row['t'] for row in self.log[start:]])


def independent_rho(solver, pressures, tip_forces=None):
    """Tip radius [m] of an independent solver at each pressure [Pa], solved in sequence."""
    out = []
    previous = None
    for k, p in enumerate(pressures):
        force = (0.0, 0.0) if tip_forces is None else tuple(tip_forces[k])
        r = solver.solve(max(float(p), 0.0), tip_force=force, initial=previous)
        assert r.success, r.message
        previous = r
        out.append(PALM_RADIUS + r.tip[1])
    return np.array(out)


def circumdiameter(points):
    """Diameter of the circle through three (x, y) points, by the perpendicular bisectors."""
    (x1, y1), (x2, y2), (x3, y3) = points
    a = np.array([[x2 - x1, y2 - y1], [x3 - x1, y3 - y1]], dtype=float)
    b = 0.5 * np.array([x2 ** 2 - x1 ** 2 + y2 ** 2 - y1 ** 2,
                        x3 ** 2 - x1 ** 2 + y3 ** 2 - y1 ** 2])
    centre = np.linalg.solve(a, b)
    return 2.0 * math.hypot(*(np.array([x1, y1]) - centre))


def fresh_solver(design):
    """
    Build a new solver of the finger the pipeline computes, sharing no state with it.

    The code under test gets its solver from `finger_model` (one cached instance); this
    is a separate instance with the node's default settings.
    """
    settings = ModelSettings()
    return AdaptiveSolver(design, tolerance=settings.tolerance,
                          pressure_model=settings.pressure_model)
