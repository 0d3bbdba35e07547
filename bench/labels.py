"""The label pass of semantic goldens in `orthosim bench --labels`: what it adds to drawing a golden (target: at most a fifth).

A golden is drawn as `orthosim_render.regression.render_case_frame` draws it: a fresh scene of the
dentition in the step's state, drawn once from one camera preset at 320x240. Its labels (what each
pixel shows and its depth) come from a second target of the same pass plus a legend
(`orthosim_render.semantic_labels.render_labelled`). Measured here, on the goldens' own subjects (the normal
occlusion in the five views, and case 1's last step with its ~1,100 contact spheres in the right
buccal view):
  - golden_ms: scene built and drawn, colour read back (the baseline);
  - labelled_ms: the same with the label target, its read-back and the legend;
  - draw_ms / labelled_draw_ms: the draw alone, the scene already built and in the GL context
    (the stricter ratio: the label target's fragment writes and read-back against a bare draw).
Each pair is timed alternately in the same run (plain, labelled, plain, ...); the label pass's cost
is the median of the `rounds` paired differences, so the ratio stands when the machine's load
moves the absolute figures.
"""

from __future__ import annotations

import statistics
import time

TARGET_RATIO = 0.2  # the label pass may cost at most a fifth of a golden's render time


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _paired(first, second, rounds: int) -> tuple[float, float, float]:
    """(median ms of `first`, median ms of `second`, median of the paired differences), timed alternately."""
    a, b = [], []
    for _ in range(rounds):
        a.append(_timed(first))
        b.append(_timed(second))
    return (1000 * statistics.median(a), 1000 * statistics.median(b),
            1000 * statistics.median(y - x for x, y in zip(a, b)))


def _subject_times(dentition, state, view: str, size, rounds: int) -> dict:
    from orthosim_render.semantic_labels import render_labelled
    from orthosim_render.frame import cached_renderer, render_state
    from orthosim_render.scene import DentitionScene

    renderer = cached_renderer(size)
    render_state(dentition, state, view, size, labels=True)  # warm: shaders compiled, trees built
    golden, labelled, label = _paired(lambda: render_state(dentition, state, view, size),
                                      lambda: render_state(dentition, state, view, size, labels=True), rounds)
    # the draw alone, one scene kept in the context (pyrender re-uploads a scene's buffers when
    # another scene was drawn in between, so this loop draws no other)
    scene = DentitionScene(dentition, size)
    scene.update(state)
    cached = renderer.static_cache
    renderer.static_cache = False  # every draw a full one, as a golden's is (its first frame)
    try:
        render_labelled(renderer, scene, view)
        draw, labelled_draw, label_draw = _paired(lambda: renderer.render(scene, view),
                                                  lambda: render_labelled(renderer, scene, view), rounds)
    finally:
        renderer.static_cache = cached
    ms = {"golden_ms": golden, "labelled_ms": labelled, "label_ms": label, "ratio": label / golden,
          "draw_ms": draw, "labelled_draw_ms": labelled_draw, "label_ms_draw_alone": label_draw,
          "ratio_draw_alone": label_draw / draw}
    return {k: round(v, 3) for k, v in ms.items()}


def label_pass_timings(size: tuple[int, int] = (320, 240), rounds: int = 7) -> dict:
    """The label pass against a golden's render on the goldens' subjects; see the module text."""
    from orthosim.exchange.case import CASES_DIR, load_case
    from orthosim_render.cameras import VIEW_NAMES
    from orthosim_render.frame_state import FrameState
    from orthosim_render.regression import simulate_case_once

    subjects = {}
    normal = load_case(CASES_DIR / "normal_occlusion.toml").build_dentition()
    for view in VIEW_NAMES:
        subjects[f"normal_occlusion_{view}"] = _subject_times(normal, FrameState.rest(normal), view, size, rounds)
    run = simulate_case_once(CASES_DIR / "case1_first_premolar_extraction.toml")
    subjects["case1_last_step_right_buccal"] = _subject_times(run.dentition, run.state(-1), "right_buccal", size, rounds)
    worst = max(s["ratio"] for s in subjects.values())
    return {"size": list(size), "rounds": rounds, "target_ratio": TARGET_RATIO, "subjects": subjects,
            "worst_ratio": round(worst, 3),
            "worst_ratio_draw_alone": round(max(s["ratio_draw_alone"] for s in subjects.values()), 3),
            "meets_target": worst <= TARGET_RATIO}
