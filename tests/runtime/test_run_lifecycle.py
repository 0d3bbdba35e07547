"""`orthosim run` as it meets the world: a bad --out or option refused before any work, SIGTERM and
SIGKILL in the middle of a rendered run, a disk that fills up; never a mixed folder, never a
process left behind."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cli_helpers import orthosim as run, orthosim_args, quick_case, reaped
from folder_helpers import earlier_run, listing

ROOT = Path(__file__).resolve().parents[2]
linux_only = pytest.mark.skipif(sys.platform != "linux", reason="reads /proc to find the run's processes")

def _descendants(pid: int) -> list[int]:
    out = []
    try:
        for task in Path(f"/proc/{pid}/task").iterdir():
            for child in (task / "children").read_text().split():
                out.append(int(child))
                out.extend(_descendants(int(child)))
    except OSError:
        pass
    return out


def _alive(pid: int) -> bool:
    """Running, or a zombie nobody reaps: either way still there."""
    return Path(f"/proc/{pid}").exists()


def _start_rendered_run(case: Path, out: Path) -> subprocess.Popen:
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    return subprocess.Popen(orthosim_args("run", case, "--out", out), cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)


def _wait_for_frames(proc: subprocess.Popen, parent: Path, n: int = 3) -> None:
    deadline = time.monotonic() + 300
    def drawn():  # into a staging folder beside the output (orthosim.runtime.outputfolder); before it, into the output
        return len([*parent.glob(".*.orthosim-staging-*/frames/*.png"), *parent.glob("*/frames/*.png")])

    n += drawn()  # an earlier run's frames
    while drawn() < n:
        assert proc.poll() is None, proc.communicate()[1]
        assert time.monotonic() < deadline, "the run drew no frames"
        time.sleep(0.05)


@pytest.mark.parametrize("make_out, expected", [
    (lambda p: (p / "file.txt").write_text("x") and p / "file.txt", "is a file, not a folder"),
    (lambda p: (p / "keep.txt").write_text("x") and p, "holds files that no orthosim run wrote"),
])
def test_a_bad_out_is_refused_in_one_line_before_the_run(tmp_path, make_out, expected):
    out = make_out(tmp_path)
    r = run("run", quick_case(tmp_path), "--out", out, "--no-render")
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and expected in r.stderr and "Traceback" not in r.stderr
    assert "steps" not in r.stdout  # no simulation ran


def test_a_bad_view_is_refused_before_any_model_or_child_process(tmp_path):
    r = run("run", quick_case(tmp_path), "--out", tmp_path / "o", "--view", "sideways")
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "--view: sideways: is not a camera preset" in lines[0], r.stderr
    assert "Traceback" not in r.stderr and "leaked" not in r.stderr
    assert not (tmp_path / "o").exists()


@linux_only
def test_sigterm_mid_run_stops_cleanly_with_143_and_leaves_the_earlier_run_whole(tmp_path):
    out = tmp_path / "o"
    earlier_run(out, frames=500)
    before = listing(out)
    proc = _start_rendered_run(quick_case(tmp_path), out)
    with reaped(proc):
        _wait_for_frames(proc, tmp_path)
        helpers = _descendants(proc.pid)
        assert helpers  # the simulation child and the video encoder
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 143
    assert stderr.strip().splitlines() == ["orthosim: terminated"]
    assert listing(out) == before  # the earlier run, untouched: no new frame mixed in
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o", "quick.toml"]  # no staging or lock left
    deadline = time.monotonic() + 5
    while any(map(_alive, helpers)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(map(_alive, helpers))


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
@linux_only
def test_after_sigkill_of_the_run_its_helper_processes_exit_by_themselves(tmp_path):
    out = tmp_path / "o"
    proc = _start_rendered_run(quick_case(tmp_path), out)
    try:
        _wait_for_frames(proc, tmp_path)
        helpers = _descendants(proc.pid)
        assert helpers
        proc.kill()  # the main process only: nothing in it runs to stop the others
        proc.wait(timeout=10)
        deadline = time.monotonic() + 3
        while any(map(_alive, helpers)) and time.monotonic() < deadline:
            time.sleep(0.05)
        left = [pid for pid in helpers if _alive(pid)]
    finally:
        if _group_alive(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)
    assert not left, f"helper processes outlived the run by 3 s: {left}"
    assert not out.exists()  # a killed run never shows up as a run folder
    rerun = run("run", quick_case(tmp_path, steps=1), "--out", out, "--no-render")
    assert rerun.returncode == 0, rerun.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o", "quick.toml"]  # the killed run's staging cleared


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
        return True
    except OSError:
        return False


@linux_only
def test_a_disk_that_fills_up_mid_run_is_one_line_and_leaves_the_folder_as_it_was(tiny_disk, tmp_path):  # noqa: F811
    out = tiny_disk / "o"
    earlier_run(out, frames=3)
    before = listing(out)
    r = run("run", quick_case(tmp_path), "--out", out)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "No space left on device" in lines[0] and "Traceback" not in r.stderr, r.stderr
    assert listing(out) == before
    assert sorted(p.name for p in tiny_disk.iterdir()) == ["o"]

