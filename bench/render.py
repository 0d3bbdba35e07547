"""`orthosim bench`: throughput of each stage, measured in one run on one case, against the 40 fps target.

What is measured (fps = 1 / median frame time after a warm-up, so a stray slow frame on a shared
machine does not move the figure; the end-to-end records also give frames / total wall time):
  - simulation: one step of the case's movement (`orthosim.movement`), whose step loop runs the
    continuous detector and reports the overlapping leaf spheres, alone;
  - collision_us_per_step: each detector alone on one whole-arch step of the same model
    (`orthosim_bench.collision.collision_timings`), and the same as fps;
  - render: draw plus colour read-back of one 640x480 frame, the scene already updated, with
    `SyntheticMotion` (all 28 teeth, 2,000 markers: the issue's worst case);
  - end_to_end: `animation.render_run` itself, the function `orthosim run` draws with, timed frame
    to frame through its `on_frame` callback, one frame per simulation step: the case simulated
    with the continuous detector in a child process (`orthosim.runtime.background.in_child_process`, as
    `orthosim run` does), its records taken off a bounded queue on a thread while render_run
    updates the scene, renders, reads back, and encodes (MP4 always, PNG frames unless disabled)
    on its background encoders; the variants compared are render_run's own parameters:
    `end_to_end_overlay` with its `caption` (the frame overlay, without and with FDI labels),
    `end_to_end_simulation_on_thread` with the simulation on that thread of this process instead
    of a child process (sharing one GIL with the drawing), `end_to_end_synthetic` with
    `SyntheticMotion` instead of the simulation, and `end_to_end_interpolated` with
    `frames_per_step` frames per simulation step (poses interpolated between steps,
    `orthosim_render.timeline`), which is what `orthosim run` writes by default;
  - end_to_end_against_stages: end to end as a share of the slower stage (target 0.85), with
    rendering read as draw + read-back and as drawing + writing frames, and of the frame rate the
    cores allow at the run's own CPU per frame;
  - render_backends: the render-alone figure through every offscreen OpenGL backend found (EGL GPU,
    EGL on Mesa's software device, OSMesa), each in its own process, and each one's ratio to OSMesa
    in the same run (`orthosim_bench.backends`);
  - render_variants: the same render with each optimisation undone in turn, measured
    round-robin in the same run so that the ratios stand even when the absolute figures wander
    with the machine's load;
  - spheretree_build: the model's sphere trees built from nothing on every core, the same in one
    process (the baseline), and loaded from the cache, in seconds (target: under 10 s to build);
  - startup_s: seconds from launching `orthosim run` to its first simulated step, warm caches
    (`orthosim_bench.startup`, target 2 s), beside a bare interpreter start in the same minute;
  - labelled_scan: a labelled arch scan of 300k+ triangles (`orthosim_bench.scanarch`) made ready to
    simulate (split, roots estimated, model and sphere trees) cold and warm, in seconds (targets 30 s / 2 s);
  - staging_s: planning time of `orthosim stage` on each shipped staging case and on a 28-tooth
    set-up of 30 stages (target: under 10 s; `orthosim_bench.staging`), and `orthosim stage verify`
    of that set-up written to disk (target: under 60 s, the whole command);
  - memory_mb: resident set size before and after a long (default 2,000 frames) update+render
    run: leaked GL programs or buffers would show there;
  - memory: peak MB of `orthosim run` for 10,000 steps without rendering and drawn into 2,000
    frames, each in a fresh child process (`orthosim_bench.memory`, target under 500 MB each);
  - label_pass (`--labels`): the label pass of semantic goldens against a golden's own render time
    (`orthosim_bench.labels`, target at most a fifth).
Components that are missing are reported as null with a "pending" note, never estimated.
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orthosim.exchange.case import DEFAULT_CASE  # the paper's case 1, as the demo: ~1,100-1,400 contact spheres a step
from orthosim_bench.spheretree import tree_build_timings
from orthosim_bench.subruns import as_records, gather, guarded

from orthosim_render.cputime import cpu_ms_per_frame, cpu_snapshot
from orthosim_render.frame_state import FrameState

TARGET_FPS = 40  # the paper's figure, with a graphics card
E2E_TARGET_FPS = 60  # issue 4's target for this 2-core machine, end to end at 640x480


def rss_mb() -> float:
    """Current resident set size of this process, MB (from /proc, Linux)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class SyntheticMotion:
    """A stand-in for the simulation: some teeth translate along the arch, contacts follow them.

    `moving` teeth slide distally and back (up to `amplitude` mm, one cycle per `period` frames).
    Each frame reports `n_markers` contact spheres taken from the crown vertices of the moving
    teeth and their neighbours (a different subset every frame, so the marker buffer changes as
    it will with a real detector), each moved with its tooth.
    """

    def __init__(self, dentition, n_markers: int = 2000, moving: tuple[int, ...] | None = None,
                 amplitude: float = 2.0, period: int = 120, seed: int = 0, extracted=frozenset()):
        self.dentition = dentition
        self.extracted = frozenset(extracted)
        fdis = [f for f in dentition.fdis if f not in self.extracted]
        if moving is None:
            moving = tuple(f for f in (13, 23, 33, 43) if f in fdis) or tuple(fdis[:2])
        self.moving = frozenset(moving)
        self.rest = dentition.rest_poses()
        self.amplitude, self.period = amplitude, period
        self.n_markers = n_markers
        self.rng = np.random.default_rng(seed)
        # marker pool: crown vertices of the moving teeth and their arch neighbours, local frames
        pairs = dentition.adjacent_pairs(set(self.extracted))
        involved = sorted({f for p in pairs for f in p if self.moving & set(p)} | set(self.moving))
        self.pool_tooth, self.pool_local = [], []
        for f in involved:
            t = dentition.teeth[f]
            v = t.mesh.vertices[np.unique(t.mesh.faces[t.face_part == 0])]
            self.pool_tooth.append(np.full(len(v), f))
            self.pool_local.append(v)
        self.pool_tooth = np.concatenate(self.pool_tooth)
        self.pool_local = np.concatenate(self.pool_local)
        self.pairs = tuple(p for p in pairs if self.moving & set(p))
        # direction of travel: distal along the arch at rest (local mesial axis, reversed)
        self.dir = {f: -(self.rest[f][:3, :3] @ dentition.teeth[f].mesial) for f in self.moving}

    def __call__(self, i: int) -> FrameState:
        s = self.amplitude * 0.5 * (1 - np.cos(2 * np.pi * i / self.period))
        poses = dict(self.rest)
        for f in self.moving:
            p = self.rest[f].copy()
            p[:3, 3] += s * self.dir[f]
            poses[f] = p
        n = min(self.n_markers, len(self.pool_local))
        idx = self.rng.choice(len(self.pool_local), n, replace=False) if n else np.zeros(0, int)
        centers = np.empty((n, 3))
        for f in np.unique(self.pool_tooth[idx]):
            sel = self.pool_tooth[idx] == f
            T = poses[int(f)]
            centers[sel] = self.pool_local[idx[sel]] @ T[:3, :3].T + T[:3, 3]
        radii = self.rng.uniform(0.15, 0.35, n)
        return FrameState(poses=poses, extracted=self.extracted, moving=self.moving, contact_centers=centers,
                          contact_radii=radii, contact_pairs=self.pairs, step=i)


def _median_fps(times: list[float]) -> float:
    return 1.0 / statistics.median(times) if times else float("nan")


def _render_variants(dentition, states, size, frames_per_round: int, rounds: int) -> dict:
    """Render fps with each optimisation undone, round-robin, plus ratios to the shipped setting."""
    from orthosim_render.renderer import Renderer
    from orthosim_render.scene import DentitionScene

    variants = {
        # name: (renderer options, scene options, what it undoes)
        "pyrender_stock_pbr": (dict(shading="pbr", lean=False), dict(marker_style="mesh"),
                               "pyrender's own forward pass and physically based shaders, markers as icospheres"),
        "stock_pass_lambert": (dict(lean=False), dict(marker_style="mesh"),
                               "our per-pixel Lambert shaders in pyrender's stock forward pass, icosphere markers"),
        "lean_pass_pixel_lit": (dict(lighting="pixel", static_cache=False), dict(marker_style="mesh"),
                                "+ lean forward pass (program, camera, lights bound once per frame)"),
        "lean_pass_vertex_lit": (dict(lighting="vertex", static_cache=False), dict(marker_style="mesh"),
                                 "+ lighting per vertex instead of per pixel"),
        "sprite_markers": (dict(static_cache=False), dict(), "+ markers as point sprites instead of icospheres"),
        "shipped": (dict(), dict(), "+ static teeth drawn once into a cached colour+depth image (the default)"),
        "shipped_msaa4": (dict(msaa=True), dict(), "the default with 4x multisampling (no static cache)"),
    }
    setups = {}
    for name, (ropts, sopts, _) in variants.items():
        r = Renderer(size, **ropts)
        sc = DentitionScene(dentition, size, **sopts)
        sc.update(states[0])
        r.render(sc)  # compile shaders, upload meshes
        setups[name] = (r, sc)
    times = {name: [] for name in variants}
    for k in range(rounds):
        for name, (r, sc) in setups.items():
            for j in range(frames_per_round):
                sc.update(states[(k * frames_per_round + j) % len(states)])
                t0 = time.perf_counter()
                r.render(sc)
                times[name].append(time.perf_counter() - t0)
    for r, _ in setups.values():
        r.close()
    base = _median_fps(times["shipped"])
    first = _median_fps(times["pyrender_stock_pbr"])
    return {
        name: {"fps": _median_fps(times[name]), "frames": len(times[name]),
               "ratio_to_shipped": _median_fps(times[name]) / base, "ratio_to_stock": _median_fps(times[name]) / first,
               "what": variants[name][2]}
        for name in variants
    }



def _against_stages(e2e: dict, fps_sim: float | None, fps_render: float, render_with_output: dict) -> dict:
    """End to end against its stages (issue 15's target: at least 0.85 of the slower of simulation
    and rendering), read two ways, and the bound the machine's cores set.

    `share_of_slower_stage` takes the stages as `fps.simulation` and `fps.render` (draw and read
    back alone, no encoding); `share_of_slower_stage_with_output` takes rendering as what it does in
    the pipeline, drawing and writing PNG frames and MP4 (`end_to_end_synthetic`: render_run fed
    with ready states). Both stages alone have the machine to themselves; end to end they share its
    cores, so the frame rate cannot pass cores / CPU per frame (`cpu_bound_fps`, from the run's own
    `cpu_ms_per_frame`): `share_of_cpu_bound` says how much of that the pipeline's overlap reaches."""
    cpu = (e2e.get("cpu_ms_per_frame") or {}).get("total")
    cores = e2e.get("cores") or os.cpu_count() or 1
    bound = 1000.0 * cores / cpu if cpu else None
    slower = min(fps_render, fps_sim) if fps_sim is not None else fps_render
    slower_out = min(render_with_output["fps"], fps_sim) if fps_sim is not None else render_with_output["fps"]
    return {"slower_stage_fps": slower, "share_of_slower_stage": e2e["fps"] / slower,
            "slower_stage_with_output_fps": slower_out, "share_of_slower_stage_with_output": e2e["fps"] / slower_out,
            "target_share": 0.85, "cpu_ms_per_frame": cpu, "cores": cores, "cpu_bound_fps": bound,
            "share_of_cpu_bound": e2e["fps"] / bound if bound else None}


def _step_against_detector(movement_model, detector: str, n_states: int, warmup: int) -> dict:
    """Informative, beside fps.simulation and collision_us_per_step (measured minutes apart, so a
    change of the machine's load between them moves their ratio): the same simulation steps again,
    each followed by one whole-arch continuous detector step (the collision bench's: rest poses to
    `perturbed_poses`, every candidate pair, all leaf pairs), medians of both and their ratio."""
    from orthosim.collision import CollisionRequest, detect_step
    from orthosim_bench.collision import perturbed_poses
    from orthosim.collision.detect import default_pairs
    from orthosim.movement.simulation import simulate as simulate_steps

    model = movement_model.collision
    rest = movement_model.dentition.rest_poses()
    end = perturbed_poses(rest)
    pairs = default_pairs(model)
    request = CollisionRequest(all_leaf_pairs=True)

    def detector_step():
        detect_step(model, rest, end, pairs=pairs, detector="continuous", request=request)

    detector_step()
    wall: dict[str, list[float]] = {"step": [], "sweep": []}
    cpu: dict[str, list[float]] = {"step": [], "sweep": []}
    gen = simulate_steps(movement_model, detector, steps=n_states)
    for i in range(n_states):
        for key, call in (("step", lambda: next(gen)), ("sweep", detector_step)):
            t0, c0 = time.perf_counter(), time.thread_time()
            call()
            if i >= warmup:
                wall[key].append(time.perf_counter() - t0)
                cpu[key].append(time.thread_time() - c0)
    gen.close()
    step_us, sweep_us = (1e6 * float(np.median(wall[k])) for k in ("step", "sweep"))
    step_cpu, sweep_cpu = (1e6 * float(np.median(cpu[k])) for k in ("step", "sweep"))
    # CPU time as well: on a loaded machine a long call is interrupted more often than a short one,
    # so the wall-time ratio grows with the load; the CPU-time ratio much less
    return {"simulation_step_us": step_us, "continuous_step_us": sweep_us, "ratio": step_us / sweep_us,
            "simulation_step_cpu_us": step_cpu, "continuous_step_cpu_us": sweep_cpu, "cpu_ratio": step_cpu / sweep_cpu,
            "target_ratio": 3.0}


def _overlay_figures(end_to_end, run_records, case_obj, detector, n_states, extracted, e2e_off,
                     rounds: int = 3) -> dict:
    """end_to_end with the frame overlay drawn (caption, day counter, legend; then with FDI labels
    too) against end_to_end without it, in `rounds` rounds of the three in turn (so a change of the
    machine's load during the bench falls on all three alike); each ratio is the median over the
    rounds of overlay fps / no-overlay fps of the same round. `e2e_off`: the run's main end-to-end
    record, reported beside them."""
    from orthosim_render.overlay import FrameCaption

    variants = {"without_overlay": None}
    for name, labels in (("overlay", False), ("overlay_with_labels", True)):
        variants[name] = FrameCaption(case_obj.name, detector, case_obj.step_days, case_obj.duration_days, labels=labels)
    fps: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(rounds):
        for name, caption in variants.items():
            with run_records(n_states - 1) as records:
                rec = end_to_end((FrameState.from_step(r, extracted) for r in records), caption=caption)
            fps[name].append(rec["fps"])
    out = {"rounds": rounds, "end_to_end_fps": e2e_off["fps"], "fps_per_round": fps}
    for name in variants:
        out[f"{name}_fps"] = float(np.median(fps[name]))
    for name in ("overlay", "overlay_with_labels"):
        ratios = [on / off for on, off in zip(fps[name], fps["without_overlay"]) if off]
        out[f"{name}_ratio"] = float(np.median(ratios)) if ratios else None
    out["target_ratio"] = 0.95
    out["meets_target"] = out["overlay_ratio"] is not None and out["overlay_ratio"] >= 0.95
    return out


@dataclass(frozen=True)
class BenchPlan:
    """What one `orthosim bench` run measures (see `run_bench`). Units: frames, pixels, days."""

    case: str | Path | None = None  # the case simulated and drawn (None: the paper's case 1)
    dentition: object = None  # a bare model instead of a case: nothing simulated
    simulate: bool = True
    detector: str = "continuous"
    frames: int = 300  # measured frames per figure, after `warmup`
    warmup: int = 30
    size: tuple[int, int] = (640, 480)
    n_markers: int = 2000  # contact markers of the synthetic motion
    memory_frames: int = 2000  # frames of the in-process memory run
    variant_rounds: int = 4
    collision_repeats: int = 20
    work_dir: str | Path | None = None
    png: bool = True
    frames_per_step: int = 6
    step_days: float | None = 2.0  # replaces the case's step (None keeps it)
    tree_build: bool = True
    startup: bool = True
    staging: bool = True
    batch: bool = False
    report: bool = False
    report_runs: str | Path | None = None
    memory: bool = False
    labels: bool = False
    scan: bool = False  # a 300k-triangle labelled arch scan made ready to simulate, cold and warm

    @property
    def case_path(self) -> Path:
        return Path(self.case) if self.case is not None else DEFAULT_CASE

    @property
    def n_states(self) -> int:
        return self.warmup + self.frames


@dataclass(frozen=True)
class _BenchModel:
    """The model the bench draws: the case's (with its step replaced) or a given dentition."""

    dentition: object
    case: object = None  # orthosim.exchange.case.Case, or None for a bare dentition
    extracted: frozenset = frozenset()
    name: str = ""

    @classmethod
    def load(cls, plan: BenchPlan) -> "_BenchModel":
        if plan.dentition is not None:
            return cls(plan.dentition, name=plan.dentition.description or "given dentition")
        import dataclasses

        from orthosim.exchange.case import load_case

        case = load_case(plan.case_path)
        if plan.step_days is not None:
            case = dataclasses.replace(case, step_days=float(plan.step_days))
        return cls(case.build_dentition(), case, frozenset(case.extractions), f"{case.name} ({plan.case_path.name})")


def run_bench(case: str | Path | None = None, *, run_case=None, **options) -> dict:
    """Measure and return the bench record (see the module docstring and the output contract).

    `options` are `BenchPlan`'s fields. `run_case(case_path, out_dir, options: RunOptions)` is the
    CLI's own run (the composition root passes it in): the batch figure times what `orthosim run`
    does, and the bench imports no CLI.

    The model is `dentition` when given (then nothing is simulated), else the case's (default:
    cases/case1_first_premolar_extraction.toml). With `simulate`, the case runs through
    `orthosim.movement` with `detector` for the simulation and end-to-end figures (the case's
    extracted teeth not drawn). The render-alone, synthetic end-to-end, variant and memory figures
    use `SyntheticMotion` on every tooth of the model (extractions ignored: the issue's worst case
    of 28 teeth) with `n_markers` markers. `step_days` replaces the case's step (None keeps it):
    a shipped case with monthly steps comes to rest after about 20 steps, and frames of teeth at
    rest would measure nothing; at 2 days a step, case 1 keeps moving through the measured frames
    (the record's `frames_with_moving_teeth` says how many did). With `tree_build`, the model's
    sphere trees are also built from nothing (`orthosim_bench.spheretree`, target 10 s). With
    `batch`, animations per minute of `orthosim batch` with 1 and 2 workers (`orthosim_bench.batch`).
    With `report`, `orthosim report` of the paper's three cases x three detectors is timed from runs in
    `report_runs` (made there first when missing; `orthosim_bench.report`, target 30 s). With
    `labels`, the label pass of semantic goldens against a golden's render (`orthosim_bench.labels`,
    target at most a fifth).
    `render_backends` (`orthosim_bench.backends`) is measured beside this record by the CLI.
    """
    from orthosim_render.renderer import Renderer
    from orthosim_render.scene import DentitionScene

    plan = BenchPlan(case=case, **options)
    t_start, load_start = time.perf_counter(), os.getloadavg()
    model = _BenchModel.load(plan)
    _compile_descent(model.dentition)  # every figure times the compiled walk, as a warm machine runs it
    failures: list = []  # orthosim_bench.subruns.Failure of every sub-run that failed or was refused
    before = _before_gl(plan, model, run_case, failures)
    synthetic = SyntheticMotion(model.dentition, n_markers=plan.n_markers)
    states = [synthetic(i) for i in range(plan.n_states)]  # render alone: the same states for every variant
    mem_start = rss_mb()
    renderer = Renderer(plan.size)
    scene = DentitionScene(model.dentition, plan.size)
    gl = {"gl_renderer": renderer.gl_renderer, "gl_version": renderer.gl_version,
          "gl_backend": renderer.backend.label}  # orthosim_render.offscreen_backend: what drew every figure but render_backends
    render_times = _render_alone(renderer, scene, states, plan.warmup)
    encode = ["MP4 encode (libx264 ultrafast)"] + (["PNG frames (orthosim_render.png)"] if plan.png else [])
    e2e_synthetic = _end_to_end(plan, model.dentition, (synthetic(i) for i in range(plan.n_states)))
    e2e_synthetic["includes"] = ["synthetic state (SyntheticMotion)", "scene update", "draw", "colour read-back", *encode]
    simulated, pending = {}, {}
    if model.case is not None and plan.simulate:
        simulated = _simulated_figures(plan, model, encode)
    else:
        pending["simulation"] = ("no case given (a bare dentition): end_to_end uses SyntheticMotion" if model.case is None
                                 else "switched off (--no-simulate): end_to_end uses SyntheticMotion")
    memory_mb = _memory_over_long_run(plan, renderer, scene, synthetic, mem_start)
    renderer.close()
    variants = _render_variants(model.dentition, states, plan.size, frames_per_round=max(10, plan.frames // 10),
                                rounds=plan.variant_rounds)
    record = _record(plan, model, before, gl, _median_fps(render_times), e2e_synthetic, simulated, pending, memory_mb,
                     variants, load_start)
    _optional_studies(plan, record, failures)
    record["failures"] = as_records(failures)
    record["wall_s"] = time.perf_counter() - t_start
    return record


def _compile_descent(dentition) -> None:
    """Compile (or load) the detectors' sphere-tree descent and the exact depth queries before
    anything is timed. The detectors compile them only once that pays
    (`orthosim.collision.descent.compiled_descent`, `orthosim.geometry.signeddistance.compiled_pays`);
    on a fresh install the bench would otherwise time numpy, then numba's compiler, then the kernels."""
    from orthosim.collision import CollisionModel
    from orthosim.collision.continuous import swept_leaves
    from orthosim.collision.detect import default_pairs
    from orthosim.collision.discrete import overlapping_leaves
    from orthosim.geometry.penetration import edge_penetration_depth
    from orthosim.geometry.signeddistance import prefer_compiled

    model = CollisionModel.from_dentition(dentition)
    poses, pairs = model.pose_array(dentition.rest_poses()), model.pair_indices(default_pairs(model))
    overlapping_leaves(model, poses, pairs, compiled=True)
    swept_leaves(model, poses, poses, pairs, compiled=True)
    prefer_compiled()
    rest = dentition.rest_poses()
    a, b = dentition.fdis[0], dentition.fdis[1]  # neighbours in the arch: b moved halfway onto a
    into = rest[b].copy()
    into[:3, 3] = 0.5 * (rest[a][:3, 3] + rest[b][:3, 3])
    edge_penetration_depth(dentition.teeth[a].mesh, rest[a], dentition.teeth[b].mesh, into)


def _before_gl(plan: BenchPlan, model: _BenchModel, run_case, failures: list) -> dict:
    """The figures taken before this process holds a GL context or threads: `orthosim run` launched
    to its first step, the model's sphere trees built from nothing (over every core and, as the
    baseline, in one process), staging, and batch throughput (its workers get the cores). Each is a
    sub-run: one that fails leaves its figure None and a `Failure` in `failures` (orthosim_bench.subruns)."""
    out: dict = {"startup": None, "trees": None, "staged": None, "batch": None, "scan": None}
    if plan.startup:
        from orthosim_bench.startup import startup_timings  # warm caches

        out["startup"] = guarded("startup", failures, lambda: startup_timings(plan.case_path))
    if plan.scan:
        from orthosim_bench.scanarch import labelled_scan_timings

        out["scan"] = guarded("labelled_scan", failures, labelled_scan_timings)
    if plan.tree_build:
        out["trees"] = guarded("spheretree_build", failures, lambda: tree_build_timings(model.dentition))
    if plan.staging:
        from orthosim_bench.staging import staging_timings

        out["staged"] = guarded("staging", failures, staging_timings)
        gather(out["staged"], "staging", failures)
    if plan.batch:
        from orthosim_bench.batch import batch_throughput

        if run_case is None:
            raise ValueError("run_bench(batch=True) needs run_case, the CLI's run of one case")
        out["batch"] = guarded("batch", failures, lambda: batch_throughput(run_case, plan.case_path))
        gather(out["batch"], "batch", failures)
    return out


def _render_alone(renderer, scene, states, warmup: int) -> list[float]:
    """Seconds of draw + read back per frame after the warm-up; the scene updated outside the timed region."""
    times = []
    for i, st in enumerate(states):
        scene.update(st)
        t0 = time.perf_counter()
        renderer.render(scene, "frontal")
        if i >= warmup:
            times.append(time.perf_counter() - t0)
    return times


def _end_to_end(plan: BenchPlan, dentition, state_iter, warm: int | None = None, caption=None) -> dict:
    """Frame-to-frame wall time of `render_run` itself, the function `orthosim run` draws with:
    states taken ahead on a thread (from a child process when `state_iter` reads one), scene
    update, render, read back, the overlay when `caption` is given (a `orthosim_render.overlay.FrameCaption`),
    encode on the sink's threads. Timed through its `on_frame` callback."""
    import tempfile

    from orthosim.runtime.options import RenderOptions
    from orthosim_render.animation import render_run

    warm = plan.warmup if warm is None else warm
    frames = plan.frames
    stamps, markers, drawn, moving = [], [], [], []
    cpu: dict = {}

    def on_frame(st, sc):
        stamps.append(time.perf_counter())
        if len(stamps) in (warm, warm + frames):  # CPU of every thread and child over the measured frames
            cpu[len(stamps)] = cpu_snapshot()
        markers.append(st.n_contacts)
        drawn.append(len(sc.markers.positions) if st.n_contacts else 0)
        moving.append(len(st.moving))

    tmp_ctx = tempfile.TemporaryDirectory(prefix="orthosim-bench-") if plan.work_dir is None else None
    out_dir = Path(plan.work_dir) if plan.work_dir is not None else Path(tmp_ctx.name)
    render_run(dentition, state_iter, out_dir, RenderOptions(size=tuple(plan.size), png=plan.png), progress=False,
               caption=caption, on_frame=on_frame)
    done = time.perf_counter()
    first = max(warm, 1)  # a frame's time runs from the frame before it
    times = np.diff(stamps)[first - 1:].tolist()
    measured = slice(warm, None)
    # frames after the warm-up over the time from the warm-up's last frame to the encoders drained
    overall = (len(stamps) - first) / (done - stamps[first - 1]) if len(stamps) > first else float("nan")
    mp4 = out_dir / "animation.mp4"
    mp4_bytes = mp4.stat().st_size if mp4.exists() else 0
    if tmp_ctx is not None:
        tmp_ctx.cleanup()
    return {"fps": _median_fps(times), "fps_overall_including_encoder_drain": overall, "mp4_bytes": mp4_bytes,
            "markers_per_frame": {"median": float(np.median(markers[measured])), "max": int(max(markers[measured]))},
            # a sphere the state lists several times is drawn once (DentitionScene.unique_markers)
            "distinct_markers_drawn_per_frame": {"median": float(np.median(drawn[measured])),
                                                 "max": int(max(drawn[measured]))},
            # share of the measured frames in which some tooth moved: a case that has come to
            # rest draws (cheaply) the same teeth again, so read the fps with this beside it
            "frames_with_moving_teeth": float(np.mean([m > 0 for m in moving[measured]])),
            # informative: where the CPU goes (ms per frame by thread group and child process);
            # the total over the machine's cores bounds the frame rate end to end can reach
            "cpu_ms_per_frame": cpu_ms_per_frame(cpu.get(warm), cpu.get(warm + frames), frames),
            "cores": os.cpu_count()}


def _simulated_figures(plan: BenchPlan, model: _BenchModel, encode: list[str]) -> dict:
    """The real thing: movement + detection per step. The simulation alone, the step against the
    continuous detector, end to end as `orthosim run` draws (simulation in a child process, on a
    thread, with interpolated frames, with the overlay) and the collision timings."""
    import functools

    from orthosim.movement.simulation import MovementModel, simulate as simulate_steps

    case, dentition, extracted, detector, n_states = model.case, model.dentition, model.extracted, plan.detector, plan.n_states
    end_to_end = functools.partial(_end_to_end, plan, dentition)
    run_records = functools.partial(_run_records, model, detector)
    movement_model = MovementModel.build(case, dentition=dentition)
    gen = simulate_steps(movement_model, detector, steps=n_states)
    sim_times = []
    for i in range(n_states):
        t0 = time.perf_counter()
        next(gen)
        if i >= plan.warmup:
            sim_times.append(time.perf_counter() - t0)
    gen.close()
    out = {"fps_sim": _median_fps(sim_times),
           "sim_vs_detector": _step_against_detector(movement_model, detector, n_states, plan.warmup)}
    # the pipeline of `orthosim run`: its own simulation side (the run strategy it would choose here,
    # orthosim.runtime.strategies: a child process, since this one holds a GL context), running ahead
    # of the drawing through a bounded queue and streaming steps.jsonl as a run does
    sim_steps = f"simulation step (orthosim.movement, {detector} detector)"
    with run_records(n_states - 1) as records:
        e2e_sim = end_to_end(FrameState.from_step(rec, extracted) for rec in records)
    e2e_sim["includes"] = [f"{sim_steps} in a child process (orthosim.runtime.strategies, as `orthosim run`), records "
                           "sent through a bounded queue", "scene update", "draw", "colour read-back", *encode]
    out["e2e_sim"] = e2e_sim
    out["e2e_overlay"] = _overlay_figures(end_to_end, run_records, case, detector, n_states, extracted, e2e_sim)
    # the same with the simulation on a thread of this process (`animation.prefetch` alone):
    # what the child process buys, measured in this run
    e2e_thread = end_to_end(FrameState.from_step(rec, extracted)
                            for rec in simulate_steps(movement_model, detector, steps=n_states - 1))
    e2e_thread["includes"] = [f"{sim_steps} on a thread of the drawing process (animation.prefetch)", *e2e_sim["includes"][1:]]
    out["e2e_thread"] = e2e_thread
    out["e2e_interp"] = (_interpolated_figure(plan, model, end_to_end, run_records, e2e_sim)
                         if plan.frames_per_step > 1 else None)
    from orthosim_bench.collision import collision_timings

    out["collision"] = collision_timings(dentition, model=movement_model.collision, repeats=plan.collision_repeats)
    return out


@contextmanager
def _run_records(model: "_BenchModel", detector: str, steps: int):
    """The step records of `orthosim run`'s own simulation side for `steps` steps of the case
    (`orthosim.runtime.strategies.step_records`: the strategy `orthosim run` would choose here)."""
    from orthosim.runtime.strategies import step_records

    with step_records(model.case, detector, steps, dentition=model.dentition) as source:  # the teeth are loaded here already
        yield source.records


def _interpolated_figure(plan: BenchPlan, model: _BenchModel, end_to_end, run_records, e2e_sim: dict) -> dict:
    """What `orthosim run` does by default: frames interpolated between steps."""
    import itertools

    from orthosim_render.timeline import frames_from_steps

    # warm up over the same simulation steps as the other figures (a case's first steps,
    # where collisions are resolved, are much slower than the rest)
    warm = 1 + (plan.warmup - 1) * plan.frames_per_step
    with run_records(plan.n_states) as records:
        steps = frames_from_steps(records, model.extracted, plan.frames_per_step)
        e2e_interp = end_to_end(itertools.islice(steps, warm + plan.frames), warm=warm)
    e2e_interp["frames_per_step"] = plan.frames_per_step
    e2e_interp["includes"] = [f"one simulation step per {plan.frames_per_step} frames, poses interpolated "
                              "between steps (orthosim_render.timeline, as `orthosim run`)", *e2e_sim["includes"]]
    return e2e_interp


def _memory_over_long_run(plan: BenchPlan, renderer, scene, synthetic, mem_start: float) -> dict:
    """Resident MB over a long run in this process (same renderer and scene: what a real run does)."""
    mem_before_long = rss_mb()
    mem_settled = mem_before_long
    settle = max(1, plan.memory_frames // 10)  # allocator pools fill during the first frames
    t0 = time.perf_counter()
    for i in range(plan.memory_frames):
        scene.update(synthetic(i))
        renderer.render(scene, ("frontal", "left_buccal")[i % 2])  # two views: two cached images
        if i == settle - 1:
            mem_settled = rss_mb()
    long_fps = plan.memory_frames / (time.perf_counter() - t0) if plan.memory_frames else None
    mem_end = rss_mb()
    return {"start": mem_start, "before_long_run": mem_before_long, f"after_{settle}_frames": mem_settled, "end": mem_end,
            "growth_after_settling": mem_end - mem_settled, "long_run_frames": plan.memory_frames, "long_run_fps": long_fps}


def _meets_targets(fps_sim, fps_render: float, e2e: dict, before: dict, collision) -> dict:
    trees, staged = before["trees"], before["staged"]
    return {
        "simulation": None if fps_sim is None else fps_sim >= TARGET_FPS,
        "render": fps_render >= TARGET_FPS,
        "end_to_end": e2e["fps"] >= TARGET_FPS,
        "end_to_end_60": e2e["fps"] >= E2E_TARGET_FPS,
        "spheretree_build": None if trees is None else trees["meets_target"],
        "staging": None if staged is None else staged["setup_28_teeth"]["staging_s"] < staged["setup_28_teeth"]["target_s"],
        "stage_verify": (None if staged is None or staged["verify_28_teeth"]["command_s"] is None
                         else staged["verify_28_teeth"]["command_s"] < staged["verify_28_teeth"]["target_s"]),
        "collision": None if collision is None else {
            k: (v is not None and 1e6 / v >= TARGET_FPS) for k, v in collision.get("collision_us_per_step", {}).items()},
    }


def _record(plan: BenchPlan, model: _BenchModel, before: dict, gl: dict, fps_render: float, e2e_synthetic: dict,
            simulated: dict, pending: dict, memory_mb: dict, variants: dict, load_start) -> dict:
    """The bench record (the output contract), from the figures measured."""
    n_tri = {f: len(model.dentition.teeth[f].mesh.faces) for f in model.dentition.fdis}
    fps_sim, collision, staged = simulated.get("fps_sim"), simulated.get("collision"), before["staged"]
    e2e = simulated.get("e2e_sim") or e2e_synthetic
    startup_record = before["startup"]
    return {
        "machine": {"cores": os.cpu_count(), **gl, "python": platform.python_version(),
                    "load_average_start": list(load_start), "load_average_end": list(os.getloadavg())},
        "target_fps": TARGET_FPS,
        "end_to_end_target_fps": E2E_TARGET_FPS,
        "model": {"source": model.name, "teeth": len(n_tri), "triangles_total": int(sum(n_tri.values())),
                  "triangles_min_per_tooth": int(min(n_tri.values())),
                  "teeth_drawn": {"synthetic": len(n_tri), "simulated": len(n_tri) - len(model.extracted)}},
        "size": list(plan.size),
        "contact_markers_render": plan.n_markers,
        "frames": plan.frames,
        "warmup": plan.warmup,
        "simulation_step_days": None if model.case is None else model.case.step_days,
        "fps": {"simulation": fps_sim, "render": fps_render, "end_to_end": e2e["fps"]},
        "meets_target": _meets_targets(fps_sim, fps_render, e2e, before, collision),
        "end_to_end": e2e,
        "end_to_end_against_stages": _against_stages(e2e, fps_sim, fps_render, e2e_synthetic),
        "end_to_end_synthetic": e2e_synthetic,
        "end_to_end_interpolated": simulated.get("e2e_interp"),
        "end_to_end_simulation_on_thread": simulated.get("e2e_thread"),
        "end_to_end_overlay": simulated.get("e2e_overlay"),
        "collision_us_per_step": None if collision is None else collision.get("collision_us_per_step"),
        "simulation_step_against_continuous_interleaved": simulated.get("sim_vs_detector"),
        "collision_fps": None if collision is None else {
            k: (1e6 / v if v else None) for k, v in collision.get("collision_us_per_step", {}).items()},
        "collision": collision,
        "spheretree_build": before["trees"],
        "startup_s": None if startup_record is None else startup_record["startup_s"],
        "startup": startup_record,
        "labelled_scan": before["scan"],
        "staging_s": None if staged is None else {**{k: v["staging_s"] for k, v in staged["cases"].items()},
                                                   "setup_28_teeth": staged["setup_28_teeth"]["staging_s"]},
        "staging": staged,
        "batch": before["batch"],
        "pending": pending,
        "render_variants": variants,
        "memory_mb": memory_mb,
    }


def _optional_studies(plan: BenchPlan, record: dict, failures: list) -> None:
    """The studies a bench run adds on request, each in its own fresh processes or renderer; each a
    sub-run whose failure leaves its figures None and a `Failure` in `failures`."""
    if plan.memory:  # peak memory of a 10,000-step run and a 2,000-frame render, each in a fresh child process
        from orthosim_bench.memory import memory_timings

        record["memory"] = guarded("memory", failures, lambda: memory_timings(plan.case_path, size=plan.size))
        gather(record["memory"], "memory", failures)
        record["meets_target"]["memory"] = None if record["memory"] is None else record["memory"]["meets_target"]
    if plan.report:  # the paper's three cases x three detectors, from runs made (or kept) beforehand
        from orthosim_bench.report import report_timings

        record["report"] = guarded("report", failures, lambda: report_timings(plan.report_runs))
        record["report_s"] = None if record["report"] is None else record["report"]["report_s"]
        record["meets_target"]["report"] = None if record["report"] is None else record["report"]["meets_target"]
    if plan.labels:  # semantic goldens: the label pass against a golden's render, 320x240
        from orthosim_bench.labels import label_pass_timings

        record["label_pass"] = guarded("label_pass", failures, label_pass_timings)
        record["meets_target"]["label_pass"] = None if record["label_pass"] is None else record["label_pass"]["meets_target"]
