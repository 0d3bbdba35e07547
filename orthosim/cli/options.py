"""Options shared by several commands: image sizes, step lists, camera views, the offscreen GL
backend and the options of every command that draws a run (`run`, `demo`, `batch`).

Each option is read here once and becomes a field of the frozen `orthosim.runtime.options.RunOptions`
or of its `RenderOptions`, under the flag's own name (`--contact-faces` is `contact_faces`); nothing
below the command line sees a flag name or a dict of options.
"""

from __future__ import annotations

import click

from orthosim.runtime.options import MIN_ANIMATION_S, RenderOptions, RunOptions

GL_CHOICES = ("auto", "egl", "osmesa")  # orthosim_render.offscreen_backend.CHOICES (not imported here: --help stays light)


def parse_size(ctx, param, value: str) -> tuple[int, int]:
    """`WIDTHxHEIGHT` in pixels (16 to 8192 each) as (width, height)."""
    try:
        w, h = (int(v) for v in value.lower().split("x"))
        if not (16 <= w <= 8192 and 16 <= h <= 8192):
            raise ValueError
    except ValueError:
        raise click.BadParameter(f"{value!r} is not WIDTHxHEIGHT in pixels (16 to 8192), e.g. 640x480") from None
    return w, h


def parse_steps(ctx, param, value: str | None) -> tuple[int, ...] | None:
    """A comma-separated list of step numbers (0 or more each), or None."""
    if value is None:
        return None
    try:
        steps = tuple(int(v) for v in value.split(","))
        if not steps or min(steps) < 0:
            raise ValueError
    except ValueError:
        raise click.BadParameter(f"{value!r} is not a comma-separated list of step numbers, e.g. 0,60,120") from None
    return steps


def parse_views(ctx, param, value: tuple[str, ...]) -> tuple[str, ...]:
    """Camera presets checked while the options are read: a bad --view stops before any work."""
    from orthosim_render.cameras import check_view  # numpy only, no OpenGL

    return tuple(check_view(v) for v in value)


def gl_option(f):
    """`--gl auto|egl|osmesa`: the offscreen OpenGL backend of a command that draws (see select_gl)."""
    return click.option("--gl", type=click.Choice(GL_CHOICES), default=None,
                        help="Offscreen OpenGL: auto (an EGL GPU, else EGL on Mesa's software device, else OSMesa), "
                             "egl or osmesa. Default: $ORTHOSIM_GL, else auto.")(f)


def select_gl(gl: str | None) -> str:
    """Choose this process's offscreen OpenGL backend now, before any work (a one-line error, exit 2,
    when it cannot start); `gl` None keeps ORTHOSIM_GL or auto. Children inherit the choice."""
    import os

    from orthosim_render.offscreen_backend import ENV, select

    if gl:
        os.environ[ENV] = gl
    return select().label


def render_options(f):
    """Options shared by the commands that draw frames."""
    f = gl_option(f)
    f = click.option("--no-render", is_flag=True, help="Run the simulation alone; write no images.")(f)
    f = click.option("--size", default="640x480", show_default=True, callback=parse_size, help="Image size WIDTHxHEIGHT.")(f)
    f = click.option("--view", "views", multiple=True, callback=parse_views,
                     help="Camera preset (repeatable): frontal, right_buccal, left_buccal, maxillary_occlusal, "
                          "mandibular_occlusal. Default: frontal.")(f)
    f = click.option("--gif", is_flag=True, help="Also write animation.gif (at the frame's size).")(f)
    f = click.option("--alpha", is_flag=True, help="PNG frames with a transparent background.")(f)
    f = click.option("--hide-roots", is_flag=True, help="Draw crowns only.")(f)
    f = click.option("--frames-per-step", default=None, type=click.IntRange(1, 120),
                     help="Animation frames per simulation step (positions interpolated between steps). "
                          "Default: enough for --seconds.")(f)
    f = click.option("--seconds", default=None, type=float,
                     help=f"Length of the animation in seconds (default: at least {MIN_ANIMATION_S:g}).")(f)
    f = click.option("--fps", default=30, show_default=True, type=int, help="Animation frames per second.")(f)
    f = click.option("--split-views", is_flag=True,
                     help="Also write each view's own PNG per frame (frames/<view>/NNNNN.png) besides the tiled frame.")(f)
    f = click.option("--export-scene", type=click.Choice(["glb", "ply"]), default=None,
                     help="Write the posed teeth at --export-steps for Blender, MeshLab or Open3D (scene/).")(f)
    f = click.option("--no-animation", is_flag=True,
                     help="Write no animation.glb (the steps as one animated glTF scene) nor viewer.html (its 3D page).")(f)
    f = click.option("--export-steps", default=None, callback=parse_steps,
                     help="Steps to export with --export-scene, comma-separated (default: first and last).")(f)
    f = click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors and warnings.")(f)
    f = click.option("-v", "--verbose", is_flag=True,
                     help="Print each phase with its time even when the output is not a terminal.")(f)
    f = click.option("--labels", is_flag=True, help="Write each crown's FDI number on the frames.")(f)
    f = click.option("--no-overlay", is_flag=True,
                     help="Bare frames: no case name, detector, day counter or colour legend drawn on them.")(f)
    f = click.option("--contact-faces", is_flag=True,
                     help="Also colour the tooth surface inside each contact sphere (as in the paper's Figure 7).")(f)
    f = click.option("--contact-faces-exact", is_flag=True,
                     help="Colour only the triangles within 0.05 mm of the tooth they touch (exact), not all inside the spheres.")(f)
    return f


def check_render_options(options: RunOptions) -> None:
    """Refuse an unknown --view, or an offscreen backend that cannot start, before any work."""
    if options.render is not None:
        from orthosim_render.cameras import check_view

        select_gl(options.render.gl)
        for view in options.render.views:
            check_view(view)


def run_options(detector: str | None, flags: dict, **chosen) -> RunOptions:
    """The RunOptions of `render_options`' flags as click gives them to a command (`--no-render`,
    `--quiet` and `--verbose` become `render=None` and `verbosity`); `chosen` sets RunOptions fields
    the command decides itself (e.g. simulate_in_process)."""
    d = RenderOptions()
    render = None if flags["no_render"] else RenderOptions(
        views=tuple(flags["views"]) or d.views, size=tuple(flags["size"]), gif=flags["gif"], alpha=flags["alpha"],
        hide_roots=flags["hide_roots"], contact_faces=flags["contact_faces"],
        contact_faces_exact=flags["contact_faces_exact"], labels=flags["labels"], overlay=not flags["no_overlay"],
        frames_per_step=flags["frames_per_step"], seconds=flags["seconds"], fps=flags["fps"],
        split_views=flags["split_views"], gl=flags["gl"],
        animation_scene=not flags["no_animation"])
    return RunOptions(detector=detector, render=render, export_scene=flags["export_scene"],
                      export_steps=flags["export_steps"], verbosity=0 if flags["quiet"] else 2 if flags["verbose"] else 1,
                      **chosen)
