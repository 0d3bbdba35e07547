"""How a tooth moves between the two ends of a step: `orthosim.geometry.motion`, named here too.

The motion lives with the geometry (numpy only) so that the drawing side, which interpolates
poses between steps, does not import the collision package and its compiled detectors (numba).
"""

from ..geometry.motion import (PosePath, chord_deviation_bound, interpolate_pose, interpolate_poses, max_speed,
                               relative_speed_bound, rotation_angle, rotation_matrix, rotation_vector)

__all__ = ["PosePath", "chord_deviation_bound", "interpolate_pose", "interpolate_poses", "max_speed",
           "relative_speed_bound", "rotation_angle", "rotation_matrix", "rotation_vector"]
