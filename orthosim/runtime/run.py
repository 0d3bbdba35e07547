"""One run of a case, in phases: validate, model, trees, simulate (and draw), write.

    result = run_one(case_path, out_dir, RunOptions(detector="discrete", render=RenderOptions(views=("frontal",))), draw=draw)

`run_one` is the whole of `orthosim run` as one function with explicit arguments (a batch calls it
once per variant; a wrapper may enclose it to stage the output folder). Its phases, in order:
  1. validate: the case file and every option, before anything heavy is imported or built, so a
     typo fails at once with one line;
  2. model: the teeth (from the dentition cache when warm, `orthosim.model.dentition_cache`) and each
     tooth's mechanics;
  3. trees: the collision model: sphere trees (cached on disk) and the exact meshes' BVHs;
  4. simulate: the movement simulation; when drawing, it runs in a child process
     (`orthosim.runtime.background`) that sends its records to this one, which draws and encodes them on
     the other core (`draw`, given by the CLI: the core never imports the renderer);
  5. write: metrics.json (only what the case and detector determine, byte-identical run to run),
     distances.csv, distances_per_step.csv, the exported scenes, and last run.json
     (`orthosim.runtime.runfolder`: what varies per run or machine: timings, frame rates, GL renderer,
     paths, options), which marks the run finished.
The child builds the model and trees once and computes the report itself; this process only loads
the teeth it draws, so nothing is built twice. Phases 2 and 3 are reported by the child as they end.
"""

from __future__ import annotations

import itertools
import math
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterable, Iterator

from orthosim.errors import OrthosimError
from orthosim.runtime.options import MIN_ANIMATION_S, SCENE_FORMATS, RenderOptions, RunOptions
from orthosim.runtime.stream import PhaseDone, RunResult, simulation_stream

_STARTED = time.perf_counter()


class OptionError(OrthosimError):
    """A command-line option asks for something the run cannot do."""


@dataclass
class RunLog:
    """Phase lines and the summary, as the options and the output (terminal or not) ask."""

    verbosity: int = 1
    tty: bool = field(default_factory=lambda: sys.stderr.isatty())
    timings_s: dict = field(default_factory=dict)

    @property
    def phases_shown(self) -> bool:
        return self.verbosity >= 2 or (self.verbosity == 1 and self.tty)

    @property
    def bars_shown(self) -> bool:
        return self.verbosity >= 1 and self.tty

    def phase(self, name: str, seconds: float, detail: str = "") -> None:
        self.timings_s[name] = round(self.timings_s.get(name, 0.0) + seconds, 4)
        if self.phases_shown:
            print(f"{name:<10} {seconds:7.2f} s  {detail}".rstrip(), file=sys.stderr, flush=True)

    def note(self, text: str) -> None:
        if self.phases_shown:
            print(text, file=sys.stderr, flush=True)

    def summary(self, text: str) -> None:
        if self.verbosity >= 1:
            print(text, flush=True)


def process_age_s() -> float:
    """Seconds since this process started (Linux /proc); since orthosim was imported elsewhere."""
    try:
        import os

        ticks = int(Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()[19])
        uptime = float(Path("/proc/uptime").read_text().split()[0])
        return uptime - ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return time.perf_counter() - _STARTED


# ------------------------------------------------------------------------------------------ 1. validate


def validate(case_path: str | Path, out_dir: str | Path, options: RunOptions, check_view: Callable[[str], str] | None = None):
    """(case, options with canonical view names and the detector filled in); one-line errors before any work.

    check_view: the renderer's view-name check (the core does not import the renderer).
    """
    from orthosim.exchange.case import DETECTORS, load_case

    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise OptionError(out_dir, None, "exists and is not a folder", "give --out a folder path")
    render = options.render and validate_render(options.render, check_view)
    if options.export_scene is not None and options.export_scene not in SCENE_FORMATS:
        raise OptionError("--export-scene", options.export_scene, "is not a scene format", f"use one of {', '.join(SCENE_FORMATS)}")
    # the options above stand alone; those below need the case (a mesh model's folders are checked too)
    case = load_case(case_path)
    detector = options.detector or case.detector
    if detector not in DETECTORS:
        raise OptionError("--detector", detector, "is not a detector", f"use one of {', '.join(DETECTORS)}")
    steps = options.export_steps
    if steps is not None:
        bad = [s for s in steps if not 0 <= s <= case.steps]
        if bad:
            raise OptionError("--export-steps", str(bad[0]), f"is not a step of this case (0 to {case.steps})",
                              f"give steps from 0 to {case.steps}")
    return case, replace(options, detector=detector, render=render)


def validate_render(render: RenderOptions, check_view: Callable[[str], str] | None = None) -> RenderOptions:
    """The drawing options with canonical view names; one-line errors for what cannot be drawn."""
    views = tuple(render.views or ("frontal",))
    if check_view is not None:
        views = tuple(check_view(v) for v in views)
    if len(set(views)) != len(views):
        raise OptionError("--view", ", ".join(views), "names a view twice", "give each view once")
    if render.frames_per_step is not None and render.seconds is not None:
        raise OptionError("--frames-per-step", str(render.frames_per_step), "and --seconds both set the animation's length",
                          "give one of them")
    if render.seconds is not None and not (0 < render.seconds <= 3600):
        raise OptionError("--seconds", f"{render.seconds:g}", "is not a length from 0 to 3600 s", "e.g. --seconds 10")
    if not 1 <= render.fps <= 120:
        raise OptionError("--fps", str(render.fps), "is not 1 to 120 frames per second", "e.g. --fps 30")
    return replace(render, views=views)


def frames_per_step(render: RenderOptions, steps: int) -> int:
    """Animation frames per simulation step: as asked, or enough for `seconds` (default MIN_ANIMATION_S)
    at `fps`; the animation has 1 + steps * frames_per_step frames."""
    if render.frames_per_step is not None:
        return render.frames_per_step
    seconds = render.seconds if render.seconds is not None else MIN_ANIMATION_S
    return max(1, math.ceil((seconds * render.fps - 1) / max(steps, 1)))


class _Split:
    """Step records out of a simulation stream; phases reported to the log, the result kept."""

    def __init__(self, items: Iterable, log: RunLog, on_record: Callable | None = None):
        self.items, self.log, self.on_record = items, log, on_record
        self.result: RunResult | None = None
        self.first_step_s: float | None = None
        self.simulation_started = time.perf_counter()  # reset when the trees phase ends
        self.steps = 0

    def __iter__(self):
        for item in self.items:
            if isinstance(item, PhaseDone):
                self.log.phase(item.name, item.seconds, item.detail)
                self.simulation_started = time.perf_counter()
            elif isinstance(item, RunResult):
                self.result = item
            else:
                if self.first_step_s is None:
                    self.first_step_s = process_age_s()
                    if self.log.verbosity >= 2:
                        self.log.note(f"first step after {self.first_step_s:.2f} s")
                self.steps += 1
                if self.on_record is not None:
                    self.on_record(item)
                yield item

    def first_read(self) -> Iterator:
        """These records, the first read now: the drawing imports its renderer (about a second)
        while the simulation computes the next steps, rather than before it takes the first."""
        items = iter(self)
        first = next(items, None)
        return items if first is None else itertools.chain((first,), items)


# ------------------------------------------------------------------------------------------ the run

def run_one(case_path: str | Path, out_dir: str | Path, options: RunOptions = RunOptions(),
            draw: Callable | None = None, check_view: Callable[[str], str] | None = None,
            shown_dir: str | Path | None = None, summary_to: Callable[[str], None] | None = None) -> dict:
    """Run one case into out_dir (see the module doc); returns the run record (run.json).

    draw(dentition, records, out_dir, options, *, extracted, per_step, total, progress, case) -> dict:
    renders the step records, as `options.render` asks, into frames and animations and returns what it measured and wrote;
    None, or options.render None: simulate only.
    shown_dir: the folder the run is meant for, named in run.json and the summary, when out_dir is
    a private staging folder that will replace it (`orthosim.runtime.outputfolder`). summary_to: receives
    the summary line (when the verbosity shows it) instead of printing it, so that a caller can
    print it once the folder is in place.
    """
    log = RunLog(options.verbosity)
    t = time.perf_counter()
    case, options = validate(case_path, out_dir, options, check_view)
    out_dir = Path(out_dir)
    render = options.render if draw is not None else None
    per_step = frames_per_step(render, case.steps) if render else None
    n_frames = 1 + case.steps * per_step if render else 0
    log.phase("validate", time.perf_counter() - t, f"{case.name}: {case.steps} steps of {case.step_days:g} days, "
                                                   f"{options.detector} detector")
    if render:
        log.note(f"{'':10} {'':9}  {n_frames} frames at {render.fps} fps ({n_frames / render.fps:.1f} s), "
                 f"views {', '.join(render.views)}, {render.size[0]}x{render.size[1]}")
    wanted = set(options.export_steps if options.export_steps is not None else (0, case.steps))
    posed: dict[int, object] = {}

    def keep(record):
        if options.export_scene and record.step in wanted:
            posed[record.step] = record

    if render:
        split, dent, rendered = _simulate_and_draw(case, options, out_dir, draw, log, keep, per_step, n_frames)
    else:
        split, dent, rendered = _Split(simulation_stream(case, options.detector, out_dir), log, keep), None, {}
        for _ in _bar(split, case.steps + 1, log):
            pass
        log.phase("simulate", time.perf_counter() - split.simulation_started, f"{split.steps} steps")
    if split.result is None:
        raise RuntimeError("the simulation ended without its report")
    scenes = _write_outputs(case, options, out_dir, split.result, dent, [posed[s] for s in sorted(posed)], log)
    log.timings_s["first_step_after_start"] = round(split.first_step_s or 0.0, 4)
    log.timings_s["total"] = round(process_age_s(), 4)
    extra = {
        "out_dir": str(Path(shown_dir or out_dir).resolve()),
        "options": {k: v for k, v in asdict(options).items() if k != "verbosity"},
        "frames_per_step": per_step,
        "timings_s": log.timings_s,
        "model_files": split.result.model_files,
        "render": {k: v for k, v in rendered.items() if k != "encode_s"} if rendered else None,
        "scenes": [str(Path(p).relative_to(out_dir)) for p in scenes],  # relative: out_dir may be a staging folder
    }
    from orthosim.runtime.runfolder import write_run_record

    record = write_run_record(out_dir, case.path, options.detector, extra)  # last: marks the run finished
    line = summary_line(case, options.detector, split.result.metrics, Path(shown_dir or out_dir))
    if summary_to is not None and options.verbosity >= 1:
        summary_to(line)
    else:
        log.summary(line)
    return record


def _simulate_and_draw(case, options: RunOptions, out_dir: Path, draw: Callable, log: RunLog, keep, per_step: int,
                       n_frames: int):
    """Simulate with the strategy the options ask for (`orthosim.runtime.strategies`) and draw every
    record as it comes; returns the record splitter, the dentition drawn and what `draw` measured."""
    from contextlib import ExitStack

    from orthosim.runtime.strategies import choose_strategy

    with ExitStack() as stack:
        strategy = choose_strategy(options.simulate_in_process or options.render.single_core)
        source = strategy.start(case, options.detector, out_dir, log, stack)
        split = _Split(source.records, log, keep)
        rendered = draw(source.dentition, split.first_read(), out_dir, options, extracted=frozenset(case.extractions),
                        per_step=per_step, total=n_frames, progress=log.bars_shown, case=case)
        log.phase("simulate", time.perf_counter() - split.simulation_started - rendered.get("encode_s", 0.0),
                  f"{split.steps} steps, {rendered.get('frames', 0)} frames drawn (simulation {source.where})")
        if "encode_s" in rendered:
            log.phase("encode", rendered["encode_s"], ", ".join(Path(p).name for p in rendered.get("outputs", {}).values()))
    return split, source.dentition, rendered


def _write_outputs(case, options: RunOptions, out_dir: Path, result, dent, posed: list, log: RunLog) -> list:
    """metrics.json, distances.csv and the exported scenes (distances_per_step.csv and steps.jsonl
    were streamed by the simulation); returns the scene files written."""
    from orthosim.storage.atomic import write_json, write_text

    t = time.perf_counter()
    write_json(out_dir / "metrics.json", result.metrics)
    write_text(out_dir / "distances.csv", result.distances_csv)
    scenes = []
    if options.export_scene:
        from orthosim.exchange.scene_export import export_scenes

        dent = dent or case.build_dentition()
        scenes = export_scenes(dent, posed, set(case.extractions), out_dir / "scene", options.export_scene)
    log.phase("write", time.perf_counter() - t, "metrics.json, distances.csv, distances_per_step.csv"
              + (f", {len(scenes)} scene files" if scenes else ""))
    return scenes


def summary_line(case, detector: str, m: dict, shown: Path) -> str:
    """The run's one summary line: distances, collisions, penetration beyond the model's own."""
    start = m.get("initial_interpenetration") or []
    initial = (f" beyond the {start[0]['mm']:.3f} mm the model starts with (teeth {start[0]['pair'][0]}-{start[0]['pair'][1]}"
               f"{f' and {len(start) - 1} more pairs' if len(start) > 1 else ''})" if start else "")
    return (f"{case.name} ({detector}): {m['steps']} steps, total distance "
            f"{m['total_distance_mm']['initial']:.2f} -> {m['total_distance_mm']['final']:.2f} mm, "
            f"{m['collisions']} collisions, max penetration {m['max_penetration_mm']:.3f} mm{initial} "
            f"-> {shown}/metrics.json")


def _bar(items: Iterable, total: int, log: RunLog) -> Iterator:
    """A tqdm bar over the steps when the log shows bars (a terminal), else the items as they are."""
    if not log.bars_shown:
        yield from items
        return
    from tqdm import tqdm

    with tqdm(items, total=total, unit="step", desc="simulate", leave=False, dynamic_ncols=True) as bar:
        yield from bar
