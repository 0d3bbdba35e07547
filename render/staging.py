"""The animation of an aligner staging (`orthosim stage`): every stage's motion, drawn by the renderer.

Between two stages each tooth follows the motion the planner checked (`orthosim.staging.plan
.path_pose`, the continuous detector's motion law), `frames_per_stage` frames a stage. Teeth moving
in a stage are tinted; where interproximal reduction was planned, the points at which the full
(unreduced) meshes of the pair meet are marked: the enamel the reduction takes away. A plan is
otherwise contact-free, so nothing else is marked.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from orthosim.staging.plan import path_pose

from orthosim_render.frame_state import FrameState

IPR_MARKER_RADIUS_MM = 0.2  # contact points have no size; drawn as spheres of this radius


def staging_frames(run, frames_per_stage: int = 6) -> Iterator[FrameState]:
    """FrameStates of a `orthosim.staging.caseplan.StagingRun`: stage 0, then `frames_per_stage`
    frames per stage, the last of each at the stage's poses."""
    from orthosim.staging.caseplan import ipr_contact_points

    plan, dent = run.plan, run.dentition
    extracted = frozenset(n for n in dent.fdis if n not in plan.teeth)
    rest = dent.rest_poses()

    def frame(poses, stage, moving):
        points, pairs = ipr_contact_points(run, stage) if plan.ipr else (np.zeros((0, 3)), ())
        return FrameState(poses={**rest, **poses}, extracted=extracted, moving=moving, contact_centers=points,
                          contact_radii=np.full(len(points), IPR_MARKER_RADIUS_MM), contact_pairs=pairs, step=stage)

    yield frame(plan.poses(0), 0, frozenset())
    for k in range(1, plan.n_stages + 1):
        p0, p1 = plan.progress[k - 1], plan.progress[k]
        moving = frozenset(n for i, n in enumerate(plan.teeth) if p1[i] > p0[i])
        for f in range(1, frames_per_stage + 1):
            t = f / frames_per_stage
            if f < frames_per_stage:
                poses = {n: path_pose(plan.start[n], plan.target[n], float(p0[i] + t * (p1[i] - p0[i])))
                         for i, n in enumerate(plan.teeth)}
                yield FrameState(poses={**rest, **poses}, extracted=extracted, moving=moving, step=k)
            else:
                yield frame(plan.poses(k), k, moving)


def render_staging(run, out_dir: str | Path, views: Sequence[str] = ("frontal",), size=(640, 480),
                   frames_per_stage: int = 6, gif: bool = False, hide_roots: bool = False) -> dict:
    """Render the staging animation into out_dir (frames/NNNNN.png, animation.mp4, optional GIF)."""
    from orthosim.runtime.options import RenderOptions
    from orthosim_render.animation import render_run

    frames = list(staging_frames(run, frames_per_stage))
    options = RenderOptions(views=tuple(views), size=tuple(size), gif=gif, hide_roots=hide_roots)
    record = render_run(run.dentition, frames, out_dir, options)
    # a longer staging staged into this folder before left more frames: they are not this plan's
    for stale in Path(out_dir, "frames").glob("[0-9][0-9][0-9][0-9][0-9].png"):
        if int(stale.stem) >= record["frames"]:
            stale.unlink()
    return record
