"""From simulation steps to animation frames: positions between steps interpolated, as in the paper.

A step of the simulation spans days; an animation wants many frames per step. Between two step
records each tooth follows the same motion the continuous collision detector assumes
(`orthosim.geometry.motion.interpolate_pose`: its local origin on a straight line, its rotation
at constant angular velocity), so what is drawn is exactly what was checked for collisions. The
contact areas drawn during a step are those found at its end, where the teeth arrive.
"""

from __future__ import annotations

from typing import Iterable, Iterator

from orthosim.geometry.motion import interpolate_pose

from orthosim_render.frame_state import FrameState


def frames_from_steps(records: Iterable, extracted: frozenset[int] = frozenset(), per_step: int = 1) -> Iterator[FrameState]:
    """FrameStates for a sequence of step records (`orthosim.movement.simulation.StepRecord`).

    The first record (the initial state) gives one frame; every later record gives `per_step`
    frames, the last of them the record itself, so the animation's time runs evenly with the
    treatment's days. A step in which nothing moved repeats one FrameState object `per_step` times
    (the renderer draws it once and repeats the image).
    """
    if per_step < 1:
        raise ValueError(f"per_step must be at least 1, got {per_step}")
    previous = None
    for record in records:
        end = FrameState.from_step(record, extracted)
        if previous is not None and per_step > 1 and not record.moving:
            for _ in range(1, per_step):
                yield end
        elif previous is not None and per_step > 1:
            for i in range(1, per_step):
                t = i / per_step
                poses = {n: (interpolate_pose(previous.poses[n], record.poses[n], t) if n in record.moving else pose)
                         for n, pose in record.poses.items()}
                yield FrameState(poses=poses, extracted=end.extracted, moving=end.moving,
                                 contact_centers=end.contact_centers, contact_radii=end.contact_radii,
                                 contact_pairs=end.contact_pairs, step=end.step)
        yield end
        previous = record
