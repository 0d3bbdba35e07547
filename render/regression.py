"""Renders for image regression tests: one simulation step of a case, in one view, at one size, as an array
(drawn by `orthosim_render.frame.render_state`, what `render_frame` draws for a script).

    from orthosim_render.regression import render_case_frame
    frame = render_case_frame("cases/case1_first_premolar_extraction.toml", step=-1, view="right_buccal")
    np.asarray(frame)   # (240, 320, 3) uint8; frame.sidecar says what drew it and what it shows

A frame is named by its simulation step (negative counts from the end, -1 = the case's last
step), not by an animation frame index, which would change with `--frames-per-step`. It is drawn
as `orthosim run` draws a step's end (same scene, colours, light rig and contact markers), with
no text overlay or anything else that is not the teeth, so a golden only changes when the teeth,
their contacts or the drawing of them change. One renderer per image size and one simulation per
case file content are kept for the life of the process: a test module rendering five views of a
case simulates it once.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orthosim import __version__
from orthosim.storage.checksums import file_sha256

from orthosim_render.frame import cached_renderer, render_state
from orthosim_render.imgdiff import GoldenSidecar

DEFAULT_SIZE = (320, 240)


@dataclass(frozen=True, eq=False)
class RenderedFrame:
    """A rendered image, (h, w, 3) uint8 RGB, what identifies it (`sidecar`) and what each pixel shows
    (`labels`, an `orthosim_render.semantic_labels.LabelFrame`, or None); usable as an array."""

    image: np.ndarray
    sidecar: GoldenSidecar
    labels: object | None = None

    def __array__(self, dtype=None, copy=None):
        return self.image if dtype is None else self.image.astype(dtype)

    @property
    def shape(self) -> tuple[int, ...]:
        return self.image.shape


def mesa_version(gl_version: str) -> str | None:
    """'4.5 (Core Profile) Mesa 22.3.6' -> '22.3.6'; None when the GL is not Mesa's."""
    match = re.search(r"Mesa (\S+)", gl_version or "")
    return match.group(1) if match else None


def gl_identity() -> GoldenSidecar:
    """This process's offscreen backend, GL renderer string and Mesa version (from its context), the rest unset."""
    r = cached_renderer(DEFAULT_SIZE)
    return GoldenSidecar(gl_renderer=r.gl_renderer, mesa_version=mesa_version(r.gl_version), gl_backend=r.backend.label,
                         orthosim_version=__version__)


def this_machine_gl() -> GoldenSidecar | None:
    """`gl_identity()`, or None when no offscreen context can start here (the comparison then uses tolerance)."""
    from orthosim_render.pyrender_setup import RenderSetupError

    try:
        return gl_identity()
    except RenderSetupError:
        return None


@dataclass(frozen=True, eq=False)
class SimulatedCase:
    """A case run once: its dentition, extracted teeth and every step record (step 0 first)."""

    case_file: Path
    case_sha256: str
    dentition: object  # orthosim.model.dentition.Dentition
    extracted: frozenset[int]
    records: tuple  # orthosim.movement.simulation.StepRecord, one per step

    def state(self, step: int = -1, contacts: bool = True):
        """The `FrameState` drawn for `step` (negative counts from the end); contacts off drops the markers."""
        from orthosim_render.frame_state import FrameState

        record = self.records[self._index(step)]
        state = FrameState.from_step(record, self.extracted)
        if not contacts:
            state = FrameState(poses=state.poses, extracted=state.extracted, moving=state.moving, step=state.step)
        return state

    def _index(self, step: int) -> int:
        n = len(self.records)
        if not -n <= step < n:
            from orthosim.errors import CaseError

            raise CaseError(self.case_file, "step", f"{step} is not a step of this case (it has steps 0 to {n - 1})",
                            f"give a step from 0 to {n - 1}, or -1 for the last")
        return step % n


@functools.lru_cache(maxsize=4)
def _simulated(case_file: Path, case_sha256: str, detector: str | None, steps: int | None) -> SimulatedCase:
    """The case simulated as `orthosim run --single-core` simulates it (`runtime.strategies.step_records`,
    in this process: the records are all needed before the first frame is drawn)."""
    from orthosim.exchange.case import load_case
    from orthosim.runtime.strategies import step_records

    case = load_case(case_file)
    with step_records(case, detector or case.detector, steps, in_process=True) as source:
        records = tuple(source.records)
    return SimulatedCase(case_file, case_sha256, source.dentition, frozenset(case.extractions), records)


def simulate_case_once(case_file: str | Path, detector: str | None = None, steps: int | None = None) -> SimulatedCase:
    """The run of `case_file` (its first `steps` steps; None: all), simulated once per process and
    file content (cached by SHA-256)."""
    from orthosim.errors import CaseError

    path = Path(case_file).resolve()
    if not path.is_file():
        raise CaseError(case_file, None, "case file not found", "give the path of a case .toml file")
    return _simulated(path, file_sha256(path), detector, steps)


def render_case_frame(case_file: str | Path, step: int = -1, view: str = "frontal",
                      size: tuple[int, int] = DEFAULT_SIZE, *, detector: str | None = None, contacts: bool = True,
                      hide_roots: bool = False, contact_faces: bool = False, labels: bool = True) -> RenderedFrame:
    """Simulation step `step` of the case (-1: its last) from camera preset `view`, at `size` (w, h) px.

    Contact markers are drawn (`contacts=False` leaves them out); `detector` defaults to the case's.
    The frame's sidecar names this process's backend, GL renderer and Mesa version, the size, view, case
    file name and SHA-256 and the step, as `orthosim imgdiff` and the pytest fixture expect. With
    `labels` (the default) the frame also carries what each pixel shows (`orthosim_render.semantic_labels`),
    drawn in the same pass, so that a failing check can say which tooth changed and how.
    """
    from orthosim_render.cameras import check_view

    view = check_view(view)
    # a step counted from the start needs only the steps up to it (never more than the case has);
    # from the end, the whole run
    steps = None
    if step >= 0:
        from orthosim.exchange.case import load_case

        steps = min(step, load_case(case_file).steps)
    run = simulate_case_once(case_file, detector, steps)
    state = run.state(step, contacts)
    image = render_state(run.dentition, state, view, size, hide_roots=hide_roots, contact_faces=contact_faces,
                         labels=labels)
    image, label_frame = image if labels else (image, None)
    gl = gl_identity()
    sidecar = GoldenSidecar(gl_renderer=gl.gl_renderer, mesa_version=gl.mesa_version, gl_backend=gl.gl_backend, size=(int(size[0]), int(size[1])),
                            view=view, orthosim_version=__version__, case_file=run.case_file.name,
                            case_sha256=run.case_sha256, frame_index=state.step)
    return RenderedFrame(image, sidecar, label_frame)
