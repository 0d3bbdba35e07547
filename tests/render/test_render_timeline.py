"""Animation frames between simulation steps follow the motion the continuous detector checks."""

from types import SimpleNamespace

import numpy as np
import pytest

from orthosim.geometry.motion import interpolate_pose
from orthosim.geometry.pose import rotation_about_axis
from orthosim_render.timeline import frames_from_steps


def record(step, poses, moving):
    return SimpleNamespace(step=step, poses=poses, moving=frozenset(moving), touching=((1, 2),),
                           contact_centers=np.zeros((1, 3)), contact_radii=np.ones(1))


def test_each_moving_step_gives_per_step_frames_on_the_detectors_motion():
    start = {11: np.eye(4), 21: np.eye(4)}
    end_11 = np.eye(4)
    end_11[:3, :3] = rotation_about_axis([0, 1, 0], np.radians(30))
    end_11[:3, 3] = [3.0, 0.0, -1.0]
    records = [record(0, start, ()), record(1, {11: end_11, 21: np.eye(4)}, (11,)), record(2, {11: end_11, 21: np.eye(4)}, ())]
    frames = list(frames_from_steps(records, per_step=4))
    # every step lasts as long on screen; a step with nothing moving repeats one state
    assert [f.step for f in frames] == [0, 1, 1, 1, 1, 2, 2, 2, 2]
    assert frames[5] is frames[6] is frames[7] is frames[8]
    for i, f in enumerate(frames[1:4], start=1):
        assert np.allclose(f.poses[11], interpolate_pose(np.eye(4), end_11, i / 4))
        assert np.allclose(f.poses[21], np.eye(4))  # a tooth at rest is not interpolated
        assert f.moving == frozenset({11}) and f.n_contacts == 1
    assert np.allclose(frames[4].poses[11], end_11)


def test_per_step_must_be_positive():
    with pytest.raises(ValueError):
        list(frames_from_steps([], per_step=0))
