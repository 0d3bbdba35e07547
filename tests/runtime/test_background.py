"""The simulation in a child process: the same records in the same order, its errors raised here,
and no process left behind however the run ends."""

from __future__ import annotations

import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from orthosim.runtime.background import ChildProcessIterator, fork_is_safe, in_child_process
from orthosim.exchange.case import DEFAULT_CASE, load_case
from orthosim.geometry import meshquery
from orthosim.errors import CaseError
from orthosim.movement.simulation import MovementModel, simulate, simulate_case

from background_helpers import endless, fails_after_two, numbers, squares_from_worker_processes, unpicklable_item

ROOT = Path(__file__).resolve().parents[2]


def _gone(pid: int) -> bool:
    """Neither running nor a zombie waiting to be reaped."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


def test_items_arrive_in_order_and_the_child_is_reaped_at_the_end():
    with in_child_process(numbers, 200, depth=3) as items:
        pid = items.pid
        assert list(items) == list(range(200))
    assert _gone(pid)


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
@pytest.mark.parametrize("dentition_sent", [True, False], ids=["dentition sent, as orthosim run", "built in the child"])
def test_a_child_simulation_yields_the_same_records_as_the_simulation_in_this_process(dentition_sent):
    case = load_case(DEFAULT_CASE)  # the paper's case 1, whose teeth move and collide
    child = ChildProcessIterator(preload=["orthosim.movement.simulation"])
    model = MovementModel.build(case)
    here = list(simulate(model, "continuous"))
    with child.submit(simulate_case, case, "continuous", dentition=model.dentition if dentition_sent else None) as records:
        there = list(records)
    assert [r.step for r in there] == [r.step for r in here] == list(range(case.steps + 1))
    assert any(r.moving for r in here) and any(r.collisions for r in here)
    for a, b in zip(here, there):
        assert a.poses.keys() == b.poses.keys()
        assert all(np.array_equal(a.poses[n], b.poses[n]) for n in a.poses)
        assert a.moving == b.moving and a.touching == b.touching
        assert np.array_equal(a.contact_centers, b.contact_centers) and np.array_equal(a.contact_radii, b.contact_radii)
        assert [(e.pair, e.time, e.impact.keys()) for e in a.collisions] == [(e.pair, e.time, e.impact.keys()) for e in b.collisions]
        assert a.max_penetration_mm == b.max_penetration_mm and a.distances == b.distances


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="fork is unavailable here")
def test_a_forked_child_simulates_a_model_built_here_as_this_process_does_without_pickling_its_work():
    case = load_case(DEFAULT_CASE)
    model = MovementModel.build(case)
    here = list(simulate(model, "continuous", 3))
    made = []

    def factory():  # a closure over a built model: spawn could not send it, fork finds it in memory
        made.append(1)
        return simulate(model, "continuous", 3)

    with in_child_process(factory, start_method="fork") as records:
        pid = records.pid
        there = list(records)
    assert not made  # it ran in the child, not here
    assert [r.step for r in there] == [r.step for r in here] == [0, 1, 2, 3]
    for a, b in zip(here, there):
        assert all(np.array_equal(a.poses[n], b.poses[n]) for n in a.poses)
        assert a.touching == b.touching and a.distances == b.distances
    assert _gone(pid)


@pytest.mark.parametrize("start_method", ["spawn", "fork"])
def test_a_child_may_start_worker_processes_of_its_own(start_method):
    # a drawn `orthosim run` with a cold sphere-tree cache builds the trees over every core inside the child
    if start_method not in multiprocessing.get_all_start_methods():
        pytest.skip(f"{start_method} is unavailable here")
    with in_child_process(squares_from_worker_processes, 5, start_method=start_method) as items:
        assert list(items) == [0, 1, 4, 9, 16]


def test_fork_is_called_safe_only_without_other_python_threads():
    import threading

    release = threading.Event()
    worker = threading.Thread(target=release.wait)
    worker.start()
    try:
        assert not fork_is_safe()
    finally:
        release.set()
        worker.join()


def test_a_forked_child_given_no_work_starts_nothing_and_closes_cleanly():
    with ChildProcessIterator(start_method="fork") as child:
        assert child.pid is None
    with pytest.raises(ValueError, match="start_method"):
        ChildProcessIterator(start_method="forkserver")
    with pytest.raises(ValueError, match="preload"):
        ChildProcessIterator(start_method="fork", preload=["numpy"])


def test_an_error_in_the_child_is_raised_here_as_the_same_error_after_the_items_before_it():
    got = []
    with pytest.raises(CaseError) as err:
        with in_child_process(fails_after_two) as items:
            pid = items.pid
            for x in items:
                got.append(x)
    assert got == ["first", "second"]
    assert str(err.value) == "case.toml: loads[0].teeth: tooth 99 does not exist (fix: use an FDI number)"
    assert _gone(pid)


def test_an_item_that_cannot_be_sent_is_an_error_not_a_silent_gap():
    with pytest.raises(Exception, match="pickle|lambda"):
        with in_child_process(unpicklable_item) as items:
            list(items)


def test_stopping_early_or_failing_in_the_consumer_stops_the_child():
    with in_child_process(endless, depth=2) as items:
        pid = items.pid
        assert next(items)[0] == 0 and next(items)[0] == 1
    assert _gone(pid)

    with pytest.raises(ZeroDivisionError):
        with in_child_process(endless) as items:
            pid = items.pid
            for x in items:
                if x[0] == 3:
                    1 / 0
    assert _gone(pid)


def test_a_child_given_no_work_is_stopped_at_once():
    started = time.monotonic()
    with ChildProcessIterator(preload=["numpy"]) as child:
        pid = child.pid
    assert _gone(pid) and time.monotonic() - started < 5


def test_a_child_that_dies_is_reported_instead_of_waited_for():
    with in_child_process(endless, depth=1) as items:
        next(items)
        os.kill(items.pid, signal.SIGKILL)
        with pytest.raises(ChildProcessError, match="exited with code -9"):
            for _ in range(10):  # a few items may already be in the queue
                next(items)


def test_remembered_exact_distances_are_fcls_own_answers():
    from orthosim.collision import CollisionModel, ExactQueries
    from orthosim_render.standin import standin_dentition

    dent = standin_dentition()
    model = CollisionModel.from_dentition(dent)
    rest = dent.rest_poses()
    a, b = dent.adjacent_pairs()[0]
    queries = ExactQueries(model)
    oa, ob = meshquery.fcl_object(dent.teeth[a].mesh), meshquery.fcl_object(dent.teeth[b].mesh)
    for dx in (0.0, -0.3, 0.5, 0.0, -0.3):  # repeats among them
        Ta = rest[a].copy()
        Ta[0, 3] += dx
        meshquery.set_pose(oa, Ta)
        meshquery.set_pose(ob, rest[b])
        assert queries.distance((a, b), {a: Ta, b: rest[b]}) == meshquery.distance(oa, ob)
    assert queries.queries == 3  # each distinct query asked of FCL once


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
@pytest.mark.skipif(sys.platform != "linux", reason="reads /proc to find the run's child processes")
def test_ctrl_c_during_a_rendered_run_stops_it_in_one_line_and_leaves_no_process(tmp_path):
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    out = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-c", "from orthosim.cli import entry; entry()", "run",
                             "cases/case1_first_premolar_extraction.toml", "--out", str(out)],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            # as from a terminal: SIGINT at its default, whatever this pytest worker inherited
                            # (an ignored signal stays ignored across exec; the run then ended with 0)
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 120
        # the run writes into a staging folder beside `out` (orthosim.runtime.outputfolder)
        while len(list(tmp_path.glob(".o.orthosim-staging-*/frames/*.png"))) < 3:
            assert proc.poll() is None and time.monotonic() < deadline, "the run ended before it could be interrupted"
            time.sleep(0.05)
        children = [int(p) for t in Path(f"/proc/{proc.pid}/task").iterdir()
                    for p in (t / "children").read_text().split()]
        assert children  # the simulation (and the video encoder)
        proc.send_signal(signal.SIGINT)
        _, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0] in ("orthosim: interrupted", "orthosim: aborted")  # click reports Ctrl-C as aborted
    deadline = time.monotonic() + 10
    while not all(_gone(pid) for pid in children) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert all(_gone(pid) for pid in children)
    assert not out.exists() and not list(tmp_path.iterdir())  # no partial, staging or temporary files
