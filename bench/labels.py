"""The label pass of semantic goldens in `orthosim bench --labels`: what it adds to drawing a golden (target: at most a fifth).

A golden is drawn as `orthosim_render.regression.render_case_frame` draws it: a fresh scene of the
dentition in the step's state, drawn once from one camera preset at 320x240. Its labels (what each
pixel shows and its depth) come from a second target of the same pass plus a legend
(`orthosim_render.labels.render_labelled`). Measured here, on the goldens' own subjects (the normal
occlusion in the five views, and case 1's last step with its ~1,100 contact spheres in the right
buccal view):
  - golden_ms: scene built and drawn, colour read back (the baseline);
  - labelled_ms: the same with the label target, its read-back and the legend;
  - draw_ms / labelled_draw_ms: the draw alone, the scene already built (the stricter ratio).
Each pair is timed round-robin in the same run (plain, labelled, plain, ...), median of `rounds`,
so the ratio stands when the machine's load moves the absolute figures.
"""

from __future__ import annotations

import statistics
import time

TARGET_RATIO = 0.2  # the label pass may cost at most a fifth of a golden's render time


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _subject_times(dentition, state, view: str, size, rounds: int) -> dict:
    from orthosim_render.labels import render_labelled
    from orthosim_render.regression import _renderer, render_state
    from orthosim_render.scene import DentitionScene

    renderer = _renderer(size)
    render_state(dentition, state, view, size, labels=True)  # warm: shaders compiled, trees built
    golden, labelled, draw, labelled_draw = [], [], [], []
    scene = DentitionScene(dentition, size)
    scene.update(state)
    cached = renderer.static_cache
    try:
        for _ in range(rounds):
            golden.append(_timed(lambda: render_state(dentition, state, view, size)))
            labelled.append(_timed(lambda: render_state(dentition, state, view, size, labels=True)))
            renderer.static_cache = False  # every draw a full one, as a golden's is (its first frame)
            draw.append(_timed(lambda: renderer.render(scene, view)))
            labelled_draw.append(_timed(lambda: render_labelled(renderer, scene, view)))
            renderer.static_cache = cached
    finally:
        renderer.static_cache = cached
    ms = {name: 1000 * statistics.median(times) for name, times in
          (("golden_ms", golden), ("labelled_ms", labelled), ("draw_ms", draw), ("labelled_draw_ms", labelled_draw))}
    ms["label_ms"] = ms["labelled_ms"] - ms["golden_ms"]
    ms["label_ms_draw_alone"] = ms["labelled_draw_ms"] - ms["draw_ms"]
    ms["ratio"] = ms["label_ms"] / ms["golden_ms"]
    ms["ratio_draw_alone"] = ms["label_ms_draw_alone"] / ms["draw_ms"]
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
