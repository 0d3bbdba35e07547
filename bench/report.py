"""The report's figure in `orthosim bench`: how long `orthosim report` takes for the paper's three
cases with three detectors each, from runs that already exist (`report_s`, target 30 s).

The runs are made first, with `orthosim run --no-render` in child processes (two at a time), into
`runs_dir` (kept between benches when given: a finished run of the same case file is reused),
then the report is built from them and timed; printing the PDF is timed apart (`pdf_s`).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from orthosim.exchange.case import CASES_DIR
from orthosim.collision.detectors import PAPER_DETECTORS as DETECTORS
from orthosim.runtime.runfolder import RunFolderError, read_finished_run
from orthosim.storage.checksums import file_sha256
from orthosim_bench.subruns import SubRunFailed, exit_failure

PAPER_CASES = ("case1_first_premolar_extraction.toml", "case2_second_premolar_extraction.toml",
               "case3_incisor_space_closure.toml")
TARGET_S = 30.0


def _ensure_run(case: Path, detector: str, run_dir: Path) -> bool:
    """Make the run unless a finished run of this very case file is there; True if it ran."""
    try:
        record = read_finished_run(run_dir)
        if record.get("case_sha256") == file_sha256(case) and record.get("detector") == detector:
            return False
    except RunFolderError:
        pass
    cmd = [sys.executable, "-c", "from orthosim.cli import entry; entry()", "run", str(case), "--detector", detector,
           "--no-render", "--out", str(run_dir)]
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    if done.returncode != 0:  # the report's figure needs every run: this one's failure is the figure's
        raise SubRunFailed("report", exit_failure("report", f"orthosim run {case.name} --detector {detector}",
                                                  done.returncode, done.stderr).why)
    return True


def _cpu_s() -> float:
    import resource

    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def report_timings(runs_dir: str | Path | None = None, out_dir: str | Path | None = None, pdf: bool = True) -> dict:
    from orthosim_render.report.page import build_report

    tmp = tempfile.TemporaryDirectory(prefix="orthosim-report-bench-")
    runs_dir = Path(runs_dir) if runs_dir is not None else Path(tmp.name) / "runs"
    out_dir = Path(out_dir) if out_dir is not None else Path(tmp.name) / "report"
    jobs = [(CASES_DIR / c, d, runs_dir / Path(c).stem / d) for c in PAPER_CASES for d in DETECTORS]
    t0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=2) as pool:
        ran = list(pool.map(lambda j: _ensure_run(*j), jobs))
    runs_s = time.perf_counter() - t0
    load = os.getloadavg()
    cpu0 = _cpu_s()
    t0 = time.perf_counter()
    report = build_report([j[2] for j in jobs], out_dir, pdf=False)
    report_s = time.perf_counter() - t0
    # CPU seconds (this process and the model builders it forked): on a shared machine the wall
    # time mostly says how busy the machine was; this says how much work the report is
    report_cpu_s = _cpu_s() - cpu0
    load_after = os.getloadavg()
    pdf_s = None
    if pdf:
        from orthosim_render.report.browser import print_pdf

        t0 = time.perf_counter()
        print_pdf(out_dir / "index.html", out_dir / "report.pdf")
        pdf_s = time.perf_counter() - t0
    tmp.cleanup()
    return {"report_s": report_s, "target_s": TARGET_S, "meets_target": report_s <= TARGET_S, "pdf_s": pdf_s, "report_cpu_s": report_cpu_s,
            "cases": len(report["cases"]), "runs": len(jobs), "runs_made": sum(ran), "runs_s": runs_s,
            "load_average_before": list(load), "load_average_after": list(load_after),
            "includes": ["reading 9 run folders", "building the teeth of each model", "distance maps and contact areas "
                         "of 12 poses", "contact tables (FCL)", "sphere-tree fit per tooth (on-disk cache)",
                         "20 pictures a case", "plots", "report.json and index.html"]}
