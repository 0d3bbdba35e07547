"""Running batches: failure isolation, resume after a kill, a Dask cluster equal to the local pool,
and sphere trees built safely when two processes need the same one at once.

The runs are small (coarse teeth, two steps, 48x32 frames); the run function is `orthosim.cli.run.run_for_batch`,
or a wrapper from `batch_helpers` that crashes, hangs or kills its worker for chosen runs.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from functools import partial
from pathlib import Path

import pytest

import batch_helpers as H
from orthosim.batch import BatchOptions, parse_sweep, plan_batch, run_batch
from orthosim.runtime.runfolder import read_finished_run

ROOT = Path(__file__).resolve().parents[2]
FORCES = "loads.0.force_cN=100,150,200"
# what a run may legitimately vary in from one process to another: timings and where it ran
VOLATILE = {"wall_s", "fps", "render_fps", "case_file", "outputs"}


@pytest.fixture(scope="module")
def case_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("cases") / "small.toml"
    path.write_text(H.SMALL_CASE)
    return path


def variants(case_file, sweep=FORCES):
    return plan_batch([case_file], sweeps=[parse_sweep(sweep)])


def ids(vs):
    return [v.run_id for v in vs]


def stable_metrics(run_dir: Path) -> dict:
    metrics = json.loads((run_dir / "metrics.json").read_text())
    return {k: v for k, v in metrics.items() if k not in VOLATILE}


def leftovers(folder: Path) -> list[Path]:
    """Temporary files an atomic write leaves when interrupted (.name.XXXX), other than the lock."""
    return [p for p in folder.rglob(".*") if p.name != ".batch.lock"]


@pytest.fixture(scope="module")
def local_batch(case_file, tmp_path_factory):
    """Three runs on two local worker processes, rendered: the reference for the other tests."""
    out = tmp_path_factory.mktemp("local")
    vs = variants(case_file)
    rows = run_batch(vs, out, H._real, BatchOptions(workers=2, run=H.RUN, progress=False), ["loads.0.force_cN"])
    return out, vs, rows


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_every_run_writes_a_finished_run_folder_and_a_row(local_batch):
    out, vs, rows = local_batch
    assert [r.status for r in rows] == ["ok"] * 3
    table = json.loads((out / "batch.json").read_text())
    assert table["runs_ok"] == 3 and table["runs_failed"] == 0
    csv = (out / "batch.csv").read_text().splitlines()
    assert csv[0].startswith("run_id,case,detector,loads.0.force_cN,status,error")
    assert len(csv) == 4
    for v, row in zip(vs, rows):
        record = read_finished_run(out / v.run_id)
        assert record["case_sha256"] == v.case_sha256  # case.toml is the exact case that ran
        assert (out / v.run_id / "case.toml").read_text() == v.case_text
        assert (out / v.run_id / "animation.mp4").stat().st_size > 0
        metrics = json.loads((out / v.run_id / "metrics.json").read_text())
        assert row.steps == metrics["steps"] == 2
        assert row.total_distance_final_mm == metrics["total_distance_mm"]["final"]
        assert row.frames == 3
    # a bigger force moves the molars further in the same time
    finals = [r.total_distance_final_mm for r in rows]
    assert finals[0] > finals[1] > finals[2]
    assert leftovers(out) == []


def test_workers_are_started_once_and_run_many_runs_each(local_batch):
    out, vs, rows = local_batch
    table = json.loads((out / "batch.json").read_text())
    workers = [r["worker"] for r in table["runs"]]
    assert len(workers) == 3 and all(workers)
    assert len(set(workers)) <= 2  # three runs on a pool of two: a process per run would show three
    assert all(r["cpu_s"] > 0 for r in table["runs"])  # each run's own CPU, for planning a batch's size


def test_the_table_is_rewritten_every_few_seconds_not_after_every_run(case_file, tmp_path, monkeypatch):
    from orthosim.batch import execute

    writes = []
    real = execute.write_table
    monkeypatch.setattr(execute, "write_table", lambda *a, **k: (writes.append(time.perf_counter()), real(*a, **k)))
    vs = variants(case_file, "loads.0.force_cN=" + ",".join(str(100 + i) for i in range(40)))
    started = time.perf_counter()
    rows = run_batch(vs, tmp_path, H.instant, BatchOptions(workers=2, progress=False), ["loads.0.force_cN"])
    elapsed = time.perf_counter() - started
    assert [r.status for r in rows] == ["ok"] * 40
    # once before the runs, at most once per TABLE_EVERY_S while they end, once at the end
    assert len(writes) <= 2 + elapsed / execute.TABLE_EVERY_S + 1
    assert len(writes) < 40
    table = json.loads((tmp_path / "batch.json").read_text())  # the last write holds every run
    assert table["runs_ok"] == 40 and [r["run_id"] for r in table["runs"]] == ids(vs)
    assert len((tmp_path / "batch.csv").read_text().splitlines()) == 41


def test_a_second_invocation_reuses_finished_runs_and_runs_nothing(local_batch):
    out, vs, _ = local_batch
    before = {v.run_id: (out / v.run_id / "run.json").stat().st_mtime_ns for v in vs}
    rows = run_batch(vs, out, partial(H.crash, fail_runs=ids(vs)), BatchOptions(workers=2, run=H.RUN,
                                                    progress=False))
    assert all(r.status == "ok" and r.reused for r in rows)  # the crashing function never ran
    assert before == {v.run_id: (out / v.run_id / "run.json").stat().st_mtime_ns for v in vs}


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_failing_runs_are_recorded_and_the_batch_goes_on(case_file, tmp_path):
    vs = variants(case_file, "loads.0.force_cN=100,150,200")
    crashing = vs[0].run_id
    opts = BatchOptions(workers=2, run=H.RUN, progress=False)
    rows = {r.run_id: r for r in run_batch(vs, tmp_path, partial(H.crash, fail_runs=[crashing]), opts)}
    assert rows[crashing].status == "failed" and rows[crashing].error == "RuntimeError: simulated crash in the renderer"
    for ok in (vs[1].run_id, vs[2].run_id):
        assert rows[ok].status == "ok", rows[ok].error
        read_finished_run(tmp_path / ok)
    assert "Traceback" in (tmp_path / "logs" / f"{crashing}.log").read_text()
    table = json.loads((tmp_path / "batch.json").read_text())
    assert (table["runs_ok"], table["runs_failed"]) == (2, 1)
    # the same command again runs the failed one only
    rows = {r.run_id: r for r in run_batch(vs, tmp_path, H._real, BatchOptions(workers=2, run=H.RUN,
                                                                                progress=False))}
    assert all(r.status == "ok" for r in rows.values())
    assert [r.reused for r in rows.values()] == [False, True, True]


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_a_hanging_run_is_stopped_at_the_run_timeout_and_the_others_finish(case_file, tmp_path):
    # the other runs end at once (the batch's own machinery is under test), so a short limit is
    # ample for them even on a loaded machine, and the test waits seconds, not minutes
    vs = variants(case_file, "loads.0.force_cN=100,150,200,250")
    hanging = vs[1].run_id
    opts = BatchOptions(workers=2, run_timeout_s=10, run=H.RUN, progress=False)
    rows = {r.run_id: r for r in run_batch(vs, tmp_path, partial(H.hang_or_instant, fail_runs=[hanging]), opts)}
    assert rows[hanging].status == "failed" and rows[hanging].error == "stopped after 10 s (--run-timeout)"
    assert [rows[v.run_id].status for v in vs if v.run_id != hanging] == ["ok"] * 3
    table = json.loads((tmp_path / "batch.json").read_text())
    assert (table["runs_ok"], table["runs_failed"]) == (3, 1)


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_a_killed_worker_costs_its_run_one_retry_or_is_recorded(case_file, tmp_path):
    vs = variants(case_file, "loads.0.force_cN=100,150")
    failing = {"fail_runs": [vs[0].run_id]}
    rows = run_batch(vs, tmp_path / "retried", partial(H.kill_worker_once, **failing, marker=str(tmp_path / "markers")),
                     BatchOptions(workers=2, run=H.RUN, progress=False))
    assert [(r.status, r.attempts) for r in rows] == [("ok", 2), ("ok", 1)]
    assert not (tmp_path / "retried" / vs[0].run_id / "partial.tmp").exists()  # the retry started from a clean folder
    rows = run_batch(vs, tmp_path / "given_up", partial(H.kill_worker_always, **failing),
                     BatchOptions(workers=2, retries=0, run=H.RUN, progress=False))
    assert rows[0].status == "failed" and rows[0].error == "the worker process died (signal SIGKILL), 1 times"
    assert rows[1].status == "ok"


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_the_command_exits_1_when_a_run_fails_and_0_when_all_succeed(case_file, tmp_path):
    args = [sys.executable, "-c", "from orthosim.cli import entry; entry()", "batch", str(case_file), "--out",
            str(tmp_path), "--size", "48x32", "--frames-per-step", "1", "--workers", "1"]
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    failed = subprocess.run(args + ["--run-timeout", "0.01"], capture_output=True, text=True, env=env, timeout=600)
    assert failed.returncode == 1, failed.stderr
    assert "stopped after 0.01 s (--run-timeout)" in failed.stderr
    done = subprocess.run(args, capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr
    assert "batch: 1 runs, 1 ok, 0 failed" in done.stdout
    run_id = json.loads((tmp_path / "batch.json").read_text())["runs"][0]["run_id"]
    options = read_finished_run(tmp_path / run_id)["options"]
    assert options["render"]["single_core"] and options["simulate_in_process"]  # the command asks each run for one core


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_a_batch_killed_mid_run_resumes_without_redoing_finished_runs(case_file, tmp_path):
    out = tmp_path / "out"
    args = [sys.executable, "-c", "from orthosim.cli import entry; entry()", "batch", str(case_file), "--out", str(out),
            "--set", FORCES, "--size", "48x32", "--frames-per-step", "1", "--workers", "1"]
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    vs = variants(case_file)
    first = out / vs[0].run_id / "run.json"
    proc = subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 600
        while not first.exists() and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.01)
        assert first.exists(), "the first run never finished"
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the batch and its workers, mid-way through the second run
        proc.wait()
    # the runs finished when the batch was killed: the first, and (where the machine was quick
    # enough to end the second in the moment the kill took) perhaps the second, never all three
    finished = {v.run_id: (out / v.run_id / "run.json").stat().st_mtime_ns
                for v in vs if (out / v.run_id / "run.json").exists()}
    assert vs[0].run_id in finished and len(finished) < len(vs)
    done = subprocess.run(args, capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr
    assert f"batch: 3 runs, 3 ok ({len(finished)} from an earlier run), 0 failed" in done.stdout
    for run_id, finished_at in finished.items():  # not run again
        assert (out / run_id / "run.json").stat().st_mtime_ns == finished_at
    for v in vs:
        read_finished_run(out / v.run_id)
    assert leftovers(out) == []


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_a_dask_cluster_gives_the_local_pools_results_and_survives_a_killed_worker(local_batch, tmp_path):
    distributed = pytest.importorskip("distributed")
    ref_out, vs, ref_rows = local_batch
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None, silence_logs=True) as cluster:
        rows = run_batch(vs, tmp_path / "dask", partial(H.kill_worker_once, fail_runs=[vs[1].run_id],
                                                        marker=str(tmp_path / "markers")),
                         BatchOptions(scheduler=cluster.scheduler_address, run=H.RUN, progress=False))
    assert (tmp_path / "markers" / vs[1].run_id).exists()  # a worker did die mid-run
    assert [r.status for r in rows] == ["ok"] * 3
    for v in vs:
        ref, got = ref_out / v.run_id, tmp_path / "dask" / v.run_id
        assert read_finished_run(got)["case_file"] == str(got / "case.toml")
        assert not (got / "partial.tmp").exists()
        assert stable_metrics(got) == stable_metrics(ref)  # bit for bit: floats compared exactly
        frames = sorted((ref / "frames").glob("*.png"))
        assert frames and [f.read_bytes() for f in frames] == [(got / "frames" / f.name).read_bytes() for f in frames]
    assert [r.total_distance_final_mm for r in rows] == [r.total_distance_final_mm for r in ref_rows]


def _build_tree(args):
    cache_dir, barrier = args
    import trimesh

    from orthosim.spheretree import cached_sphere_tree

    mesh = trimesh.creation.icosphere(subdivisions=2, radius=5.0)
    barrier.wait()  # both processes ask for the same missing tree at the same moment
    tree = cached_sphere_tree(mesh, cache_dir=cache_dir)
    return [c.tolist() for c in tree.centers], [r.tolist() for r in tree.radii]


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_two_processes_building_the_same_tree_at_once_leave_one_whole_cache_entry(tmp_path):
    import trimesh

    from orthosim.spheretree import cached_sphere_tree

    ctx = multiprocessing.get_context("spawn")
    barrier = ctx.Manager().Barrier(2)
    with ctx.Pool(2) as pool:
        a, b = pool.map(_build_tree, [(str(tmp_path), barrier)] * 2)
    entries = list(tmp_path.iterdir())
    assert len(entries) == 1 and entries[0].suffix == ".npz"  # one entry, no temporary file left
    stored = cached_sphere_tree(trimesh.creation.icosphere(subdivisions=2, radius=5.0), cache_dir=tmp_path)  # a hit
    assert a == b == ([c.tolist() for c in stored.centers], [r.tolist() for r in stored.radii])
    assert list(tmp_path.iterdir()) == entries


def test_the_batch_builds_each_models_trees_before_its_workers_start(case_file, tmp_path, monkeypatch):
    from orthosim.batch import execute

    built = []
    monkeypatch.setattr(execute, "prebuild_trees", lambda files: built.extend(files))
    vs = variants(case_file) + plan_batch([case_file], sweeps=[parse_sweep("model.resolution=medium")])
    run_batch(vs, tmp_path, partial(H.crash, fail_runs=ids(vs)), BatchOptions(workers=1, progress=False))
    # one case file per distinct model (three coarse variants share one), each written before the build
    assert [p.parent.name for p in built] == [vs[0].run_id, vs[3].run_id]


def test_the_bench_figure_runs_the_same_runs_on_a_cold_pool_of_one_and_of_two_workers(case_file):
    from orthosim_bench.batch import batch_throughput

    record = batch_throughput(H.instant, case_file, runs=6)
    assert record["runs"] == 6 and "6 runs" in record["batch_size_why"]
    assert not [k for k in record if k.startswith("errors_")]
    one, two = record["detail_1_worker"], record["detail_2_workers"]
    assert one["worker_processes"] == 1 and 1 <= two["worker_processes"] <= 2
    for name in ("1_worker", "2_workers"):
        assert record[f"per_minute_{name}"] == pytest.approx(6 / record[f"wall_s_{name}"] * 60)
        assert record[f"detail_{name}"]["workers_cpu_s_per_run"] > 0  # the workers' start-up at least
    assert record["ratio_2_to_1"] == pytest.approx(record["per_minute_2_workers"] / record["per_minute_1_worker"])
    assert record["meets_target"] == (record["ratio_2_to_1"] >= record["target_ratio_2_to_1"])
    # two workers can never do more than twice the work of one, however idle one leaves the cores
    assert record["ratio_ceiling"] == pytest.approx(min(2.0, record["cores"] / one["cores_busy"]))
    assert record["ratio_ceiling"] <= 2.0
