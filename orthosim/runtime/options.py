"""What a user asks of a run, as two frozen values that travel whole from the command line to the
renderer: `RenderOptions` (how the frames are drawn and written) inside `RunOptions` (the run as a
whole: detector, what else is written, where the simulation runs, how much is printed).

Each option has one name from the flag to the renderer (`--contact-faces` is `contact_faces`
everywhere); the command line (`orthosim.cli.options`) builds these values from its flags, and
nothing below it sees a flag name or a dict of options. The core defines them, so that it can
validate and record them, and the renderer (`orthosim_render.animation.render_run`) reads them; the
core never imports the renderer.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

MIN_ANIMATION_S = 5.0  # default animation length: at least this many seconds
SCENE_FORMATS = ("glb", "ply")


@dataclass(frozen=True)
class RenderOptions:
    """How a run's frames are drawn and written.

    views: camera presets (`orthosim_render.cameras`), tiled left to right in each frame.
    size: (width, height) of each view's image, pixels.
    gif / png / mp4: write animation.gif, frames/NNNNN.png, animation.mp4.
    alpha: PNG frames with a transparent background.
    hide_roots: draw crowns only.
    contact_faces: colour the tooth surface inside each contact sphere; contact_faces_exact: only
        the triangles within the touch tolerance of the tooth they touch.
    labels: each crown's FDI number drawn on the frames (needs `overlay`).
    overlay: case, detector, day N of M and the colour legend drawn on the frames.
    frames_per_step / seconds: animation frames per simulation step, or the animation's length in
        seconds at `fps`; neither: at least MIN_ANIMATION_S seconds.
    fps: animation frames per second.
    split_views: also write each view's own PNG per frame (frames/<view>/NNNNN.png).
    single_core: draw and encode on the calling thread, ffmpeg on one thread (a batch worker, one
        per core); a run alone wants the pipeline, which keeps more than one core busy.
    gl: the offscreen OpenGL backend asked for: "auto", "egl", "osmesa"; None: $ORTHOSIM_GL, else auto.
    animation_scene: also write animation.glb (every step a keyframe) and viewer.html (--no-animation: not).
    """

    views: tuple[str, ...] = ("frontal",)
    size: tuple[int, int] = (640, 480)
    gif: bool = False
    png: bool = True
    mp4: bool = True
    alpha: bool = False
    hide_roots: bool = False
    contact_faces: bool = False
    contact_faces_exact: bool = False
    labels: bool = False
    overlay: bool = True
    frames_per_step: int | None = None
    seconds: float | None = None
    fps: int = 30
    split_views: bool = False
    single_core: bool = False
    gl: str | None = None
    animation_scene: bool = True


@dataclass(frozen=True)
class RunOptions:
    """What the user asked of a run, besides the case (all validated by `orthosim.runtime.run.validate`).

    detector: the collision detector; None: the case's own.
    render: how to draw the frames; None: simulate only, write no images.
    export_scene: "glb" or "ply": the posed teeth at `export_steps` (default: first and last step).
    simulate_in_process: simulate in this process rather than in a child (batch workers: one per
        core already).
    verbosity: 0 quiet (errors and warnings only), 1 normal (phase lines and bars on a terminal,
        the summary line), 2 verbose (phase lines wherever the output goes).
    """

    detector: str | None = None
    render: RenderOptions | None = RenderOptions()
    export_scene: str | None = None
    export_steps: tuple[int, ...] | None = None
    simulate_in_process: bool = False
    verbosity: int = 1

    def on_one_core(self) -> RunOptions:
        """These options for a run that keeps to one core (an `orthosim batch` worker, one per core): the
        simulation in this process, and drawing and encoding on one thread (`RenderOptions.single_core`)."""
        render = None if self.render is None else replace(self.render, single_core=True)
        return replace(self, simulate_in_process=True, render=render)
