"""Three-finger grasps: objects, the pressure path, grasp and holding forces, `fpc-grasp`."""

from .finger import FingerGrasp
from .grasp import (GraspPoint, GraspSettings, GraspStatus, GraspSweep, holding_force,
                    simulate_grasp)
from .objects import Box, CoaxialCylinder, CrossCylinder, make_object, Sphere

__all__ = ['Box', 'CoaxialCylinder', 'CrossCylinder', 'FingerGrasp', 'GraspPoint', 'GraspSettings',
           'GraspStatus', 'GraspSweep', 'Sphere', 'holding_force', 'make_object',
           'simulate_grasp']
