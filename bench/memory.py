"""Peak memory of long runs, each measured on `orthosim run` launched as a fresh child process.

`orthosim bench` records two figures (target: under 500 MB each), so that memory that grows with a
run's length shows as a number rather than as a machine that starts swapping. Each is the run's
private memory: the peak over the run of the summed Private_Dirty (/proc/PID/smaps_rollup) of its
process tree, the pages only its processes hold and have written, which only swap could take back
(a library's clean pages, which the kernel drops by itself, do not count). The resident figures
described below stay beside it (`*_resident_mb`):
  - `run_10k_steps_no_render_mb`: a case run for 10,000 simulation steps with `--no-render`
    (every step's record streams to steps.jsonl; nothing should grow with the step count);
  - `render_2000_frames_mb`: the case drawn into at least 2,000 frames at 640x480 (PNG frames and
    the MP4), the simulation in its own child process as `orthosim run` does.
Each is the peak, over the run, of the memory of the launched process and all its descendants (the
simulation child, the video encoder), sampled from /proc while it runs, and never less than the
largest high-water mark (VmHWM) of any single process of that tree, which the kernel keeps so that
no sampling can miss a process's own peak. Which memory: the tree's distinct resident physical
pages (from /proc/PID/pagemap, every `unique_interval_s`), each page once however many of the
tree's processes map it. That is what the run takes from the machine. Summed RSS, kept beside it,
counts every page a forked child shares with its parent twice (the simulation child is a fork made
after the shared imports and the model load: ~70 MB of libraries and objects counted twice); PSS, kept
beside it too, splits each shared page among all processes mapping it, including processes outside
the run (other programs mapping the same libraries), so it reads low on a busy machine. Reading
page frames needs CAP_SYS_ADMIN (root); without it the headline is the PSS and `peak_measure` says
so. Not the kernel's `ru_maxrss` of the child: it keeps the RSS of the process that forked it (the
bench itself, hundreds of MB) as it was at exec. The launching process's memory never counts.
Linux only (/proc).
"""

from __future__ import annotations

import dataclasses
import math
import os
import subprocess
import sys
import tempfile
import time
import tomllib
from dataclasses import asdict, dataclass
from pathlib import Path

from orthosim_bench.subruns import exit_failure, last_line

TARGET_MB = 500.0


@dataclass(frozen=True)
class PeakMemory:
    """What one measured child run used: `peak_mb` is the figure to read (see the module docstring)."""

    peak_mb: float  # the figure checked against the target (module doc): max(tree's unique pages, or its PSS, largest VmHWM), MB
    tree_rss_sampled_peak_mb: float  # summed RSS of the process tree, highest sample, MB (counts a page shared by n processes n times)
    tree_pss_sampled_peak_mb: float  # summed PSS (each shared page split among all processes mapping it), highest sample, MB
    tree_unique_sampled_peak_mb: float | None  # distinct physical pages resident in the tree, highest sample (every unique_interval_s), MB; None where page frames are hidden
    peak_measure: str  # "unique pages" or "PSS": what peak_mb is made of
    tree_private_dirty_peak_mb: float  # summed Private_Dirty of the tree, highest sample, MB: memory only swap could take back
    tree_uss_peak_mb: float  # summed USS (Private_Clean + Private_Dirty) of the tree, highest sample, MB
    largest_process_peak_mb: float  # the largest VmHWM of one process of the tree, MB
    processes_seen: int  # distinct processes of the tree seen while sampling
    process_peaks_mb: tuple[tuple[str, float], ...]  # (command name, VmHWM MB) of each process seen, largest first
    samples: int
    wall_s: float
    exit_code: int  # the run's exit status: any but 0 and its figures are null (`memory_timings`)
    stderr_tail: str = ""  # the run's last line of standard error, where it was kept


def _children(pid: int) -> list[int]:
    out = []
    try:
        for tid in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{tid}/children") as f:
                out.extend(int(c) for c in f.read().split())
    except (OSError, ValueError):
        pass
    return out


def _rss_and_hwm_kb(pid: int) -> tuple[int, int]:
    """(VmRSS, VmHWM) of a process, kB; (0, 0) once it is gone."""
    rss = hwm = 0
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    rss = int(line.split()[1])
                elif line.startswith("VmHWM:"):
                    hwm = int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return rss, hwm


_ROLLUP_FIELDS = ("Pss", "Private_Clean", "Private_Dirty", "Anonymous")


def _rollup_kb(pid: int) -> dict[str, int]:
    """A process's /proc/PID/smaps_rollup figures, kB: Pss (each shared page split among the processes
    sharing it), Private_Clean and Private_Dirty (pages only this process maps: their sum is smem's
    USS), Anonymous; zeros once it is gone."""
    out = dict.fromkeys(_ROLLUP_FIELDS, 0)
    try:
        with open(f"/proc/{pid}/smaps_rollup") as f:
            for line in f:
                key, _, rest = line.partition(":")
                if key in out:
                    out[key] = int(rest.split()[0])
    except (OSError, ValueError, IndexError):
        pass
    return out


_PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096
_PFN_MASK = (1 << 55) - 1
_PRESENT = 1 << 63


class _Hidden(Exception):
    """Page frame numbers read as zeros: reading them needs CAP_SYS_ADMIN."""


def _frames(pid: int):
    """The physical page frame numbers of a process's resident pages (a numpy array), from
    /proc/PID/pagemap; None when it cannot be read now (gone, or changing: an exec). Raises `_Hidden`
    when the kernel hides the frames."""
    import numpy as np

    found = []
    try:
        with open(f"/proc/{pid}/maps") as maps, open(f"/proc/{pid}/pagemap", "rb", buffering=0) as pagemap:
            fd = pagemap.fileno()
            for line in maps:
                lo, hi = (int(x, 16) for x in line.split(None, 1)[0].split("-"))
                if line.rstrip().endswith("[vsyscall]"):
                    continue
                data = os.pread(fd, (hi - lo) // _PAGE * 8, lo // _PAGE * 8)
                entries = np.frombuffer(data, np.uint64)
                found.append(entries[(entries & np.uint64(_PRESENT)) != 0] & np.uint64(_PFN_MASK))
    except (OSError, ValueError):
        return None
    frames = np.concatenate(found) if found else np.zeros(0, np.uint64)
    if len(frames) and not frames.any():
        raise _Hidden(pid)
    return frames


def _tree_unique_kb(pids) -> int:
    """kB of distinct physical pages resident in any process of `pids` (each page once, however many
    of them map it); 0 when a process could not be read this time (the sample is skipped). Raises
    `_Hidden` when page frames cannot be read here."""
    import numpy as np

    parts = []
    for p in pids:
        frames = _frames(p)
        if frames is None:
            return 0
        parts.append(frames)
    if not parts:
        return 0
    return int(len(np.unique(np.concatenate(parts)))) * _PAGE // 1024


def _command(pid: int) -> str:
    """The start of a process's command line (program name and its first arguments), for the record."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            words = [w.decode(errors="replace") for w in f.read().split(b"\0") if w]
        return " ".join([os.path.basename(words[0]), *words[1:4]]).replace("\n", " ")[:100] if words else "?"
    except OSError:
        return "?"


def _tree(pid: int) -> list[int]:
    seen, todo = [], [pid]
    while todo:
        p = todo.pop()
        seen.append(p)
        todo.extend(_children(p))
    return seen


def measure_peak_memory(argv: list[str], *, cwd: str | Path | None = None, env: dict | None = None,
                        interval_s: float = 0.05, unique_interval_s: float = 1.0, timeout_s: float = 3600.0,
                        stderr=subprocess.DEVNULL) -> PeakMemory:
    """Run `argv` as a child process to its end and return its peak memory (`PeakMemory`, MB).

    Standard output is discarded, standard error too unless `stderr` (a file) is given. A run still
    going after `timeout_s` is killed (its exit code then says so).
    """
    if not os.path.isdir("/proc/self/task"):
        raise OSError("measuring a process tree's memory needs Linux's /proc")
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=stderr)
    tree_kb, pss_kb, hwm_kb, samples, seen, names = 0, 0, {}, 0, set(), {}
    dirty_kb = uss_kb = 0
    unique_kb: int | None = 0
    next_unique = time.monotonic()
    deadline = time.monotonic() + timeout_s
    while proc.poll() is None:
        pids = _tree(proc.pid)
        seen.update(pids)
        total = 0
        for p in pids:
            if p not in names:
                names[p] = _command(p)
            rss, hwm = _rss_and_hwm_kb(p)
            total += rss
            hwm_kb[p] = max(hwm_kb.get(p, 0), hwm)
        tree_kb = max(tree_kb, total)
        rollups = [_rollup_kb(p) for p in pids]
        pss_kb = max(pss_kb, sum(r["Pss"] for r in rollups))
        dirty_kb = max(dirty_kb, sum(r["Private_Dirty"] for r in rollups))
        uss_kb = max(uss_kb, sum(r["Private_Clean"] + r["Private_Dirty"] for r in rollups))
        if unique_kb is not None and time.monotonic() >= next_unique:  # tens of ms a time: every unique_interval_s
            try:
                unique_kb = max(unique_kb, _tree_unique_kb(pids))
            except _Hidden:
                unique_kb = None
            next_unique = time.monotonic() + unique_interval_s
        samples += 1
        if time.monotonic() > deadline:
            proc.kill()
            proc.wait()
            break
        time.sleep(interval_s)
    tree_mb, largest_mb = tree_kb / 1024.0, max(hwm_kb.values(), default=0) / 1024.0
    unique_mb = None if unique_kb is None else unique_kb / 1024.0
    headline = unique_mb if unique_mb is not None else pss_kb / 1024.0
    return PeakMemory(peak_mb=max(headline, largest_mb), tree_rss_sampled_peak_mb=tree_mb,
                      tree_pss_sampled_peak_mb=pss_kb / 1024.0, tree_unique_sampled_peak_mb=unique_mb,
                      peak_measure="unique pages" if unique_mb is not None else "PSS",
                      tree_private_dirty_peak_mb=dirty_kb / 1024.0, tree_uss_peak_mb=uss_kb / 1024.0,
                      largest_process_peak_mb=largest_mb, processes_seen=len(seen),
                      process_peaks_mb=tuple(sorted(((names.get(p, "?"), kb / 1024.0) for p, kb in hwm_kb.items()),
                                                    key=lambda item: -item[1])),
                      samples=samples,
                      wall_s=time.perf_counter() - t0, exit_code=proc.returncode)


def _orthosim_argv(*args: str | Path) -> list[str]:
    return [sys.executable, "-c", "from orthosim.cli import entry; entry()", *map(str, args)]


def long_run_step_days(case_step_days: float, steps: int) -> float:
    """Days per step for a run of `steps` steps that stays within the case ranges' longest treatment
    (`orthosim.exchange.case.RANGES["duration_days"]`, five years): the case's own step when that fits,
    else a shorter one (0.18 days for 10,000 steps), rounded down to 0.01 day."""
    from orthosim.exchange.case import RANGES

    longest_days = RANGES["duration_days"][1]
    if steps * case_step_days <= longest_days:
        return case_step_days
    return math.floor(100.0 * longest_days / steps) / 100.0


def _case_with_steps(case: Path, steps: int, folder: Path) -> Path:
    """A copy of `case` in `folder` whose treatment lasts `steps` steps (the case's own step, or a
    shorter one so that the treatment stays within the case ranges: `long_run_step_days`; mesh
    folders made absolute). Checked as a case before any child runs it."""
    import tomli_w

    from orthosim.exchange.case import load_case

    loaded = load_case(case)  # validated first: a bad case is the bench's error, not a child's
    step_days = long_run_step_days(loaded.step_days, steps)
    raw = tomllib.loads(Path(case).read_text())
    raw.setdefault("treatment", {})["step_days"] = step_days
    raw["treatment"]["duration_days"] = round(steps * step_days, 6)
    model = raw.get("model", {})
    if "folder" in model:
        model["folder"] = ([str(f) for f in loaded.model.folders] if isinstance(model["folder"], list)
                           else str(loaded.model.folder))
    out = folder / f"{Path(case).stem}_{steps}_steps.toml"
    out.write_text(tomli_w.dumps(raw))
    if load_case(out).steps != steps:  # the copy must be a case the ranges allow, of the steps asked
        raise ValueError(f"{out.name}: {load_case(out).steps} steps, not {steps}")
    return out


def _measured_run(argv: list[str], folder: Path, name: str) -> PeakMemory:
    """`measure_peak_memory` of one `orthosim run`, its standard error kept in `folder` for a failure's line."""
    env = dict(os.environ)  # ORTHOSIM_GL / PYOPENGL_PLATFORM: the backend this bench chose
    with open(folder / f"{name}.stderr", "w+b") as err:
        peak = measure_peak_memory(argv, env=env, stderr=err)
        err.seek(0)
        said = err.read()[-4000:]
    return dataclasses.replace(peak, stderr_tail=last_line(said))


def memory_timings(case: str | Path, *, steps: int = 10_000, frames: int = 2_000, size: tuple[int, int] = (640, 480),
                   work_dir: str | Path | None = None) -> dict:
    """The bench's `memory` record: peak MB of a `steps`-step run without rendering and of a run drawn
    into at least `frames` frames at `size`, each `orthosim run` in a fresh child process. A run that
    exits non-zero leaves its figure null, its `meets_target` null and a line in `failures`."""
    from orthosim.exchange.case import load_case

    load_start = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="orthosim-memory-", dir=work_dir) as tmp:
        tmp = Path(tmp)
        long_case = _case_with_steps(Path(case), steps, tmp)
        no_render = _measured_run(_orthosim_argv("run", long_case, "--out", tmp / "no_render", "--no-render", "--quiet"),
                                  tmp, "no_render")
        case_steps = load_case(case).steps
        per_step = max(1, math.ceil((frames - 1) / case_steps))
        drawn_frames = 1 + case_steps * per_step
        rendered = _measured_run(_orthosim_argv("run", case, "--out", tmp / "render", "--frames-per-step", per_step,
                                                "--size", f"{size[0]}x{size[1]}", "--quiet"), tmp, "render")
    record = _memory_record(no_render, rendered)
    record["run_no_render"] = {"case": str(case), "steps": steps, "step_days": long_run_step_days(load_case(case).step_days, steps),
                               **asdict(no_render)}
    record["render"] = {"case": str(case), "steps": case_steps, "frames_per_step": per_step, "frames": drawn_frames,
                        "size": list(size), **asdict(rendered)}
    record["load_average_start"] = list(load_start)
    record["load_average_end"] = list(os.getloadavg())
    return record


def _memory_record(no_render: PeakMemory, rendered: PeakMemory) -> dict:
    """The figures of the two runs; a run that failed gives nulls and a failure (orthosim_bench.subruns)."""
    runs = {"run_10k_steps_no_render": no_render, "render_2000_frames": rendered}
    ok = {name: peak.exit_code == 0 for name, peak in runs.items()}

    def figure(name: str, value: float) -> float | None:
        return value if ok[name] else None

    failures = [asdict(exit_failure(f"{name}_mb", "orthosim run", peak.exit_code, peak.stderr_tail))
                for name, peak in runs.items() if not ok[name]]
    # The headline is private memory: pages only the run's processes hold and have written (heap,
    # arrays, copies made on write; Private_Dirty). That is what the kernel cannot take back without
    # swap; a library's clean pages (numba's and llvmpipe's LLVM) it drops by itself under pressure.
    return {
        "run_10k_steps_no_render_mb": figure("run_10k_steps_no_render", no_render.tree_private_dirty_peak_mb),
        "render_2000_frames_mb": figure("render_2000_frames", rendered.tree_private_dirty_peak_mb),
        "target_mb": TARGET_MB,
        # a run that did not finish meets nothing: null, never true
        "meets_target": {name: (peak.tree_private_dirty_peak_mb < TARGET_MB if ok[name] else None)
                         for name, peak in runs.items()},
        "failures": failures,
        # the distinct resident pages of the tree (libraries' clean pages included), as before
        "run_10k_steps_no_render_resident_mb": figure("run_10k_steps_no_render", no_render.peak_mb),
        "render_2000_frames_resident_mb": figure("render_2000_frames", rendered.peak_mb),
        # private memory: pages only the run's processes hold; Private_Dirty (heap, arrays, written
        # copies) is what the kernel cannot take back without swap, whatever a process does with its
        # clean file pages (libraries, which the kernel drops itself under pressure)
        "run_10k_steps_no_render_uss_mb": figure("run_10k_steps_no_render", no_render.tree_uss_peak_mb),
        "render_2000_frames_uss_mb": figure("render_2000_frames", rendered.tree_uss_peak_mb),
        "run_10k_steps_no_render_rss_mb": figure("run_10k_steps_no_render", no_render.tree_rss_sampled_peak_mb),
        "render_2000_frames_rss_mb": figure("render_2000_frames", rendered.tree_rss_sampled_peak_mb),
        "render_2000_frames_pss_mb": figure("render_2000_frames", rendered.tree_pss_sampled_peak_mb),
        "measure": rendered.peak_measure,
        "how": "orthosim run in a fresh child process; headline: peak of the summed Private_Dirty of its process "
               "tree (/proc/PID/smaps_rollup), with the USS beside it; *_resident_mb: peak of the distinct physical "
               "pages resident in the tree (each page once: /proc/PID/pagemap; PSS where page frames are hidden), at "
               "least the largest VmHWM of one process; the summed RSS and PSS beside them; a run that exits "
               "non-zero gives nulls and a line in failures",
    }
