"""A batch worker's run keeps to one core, and a batch worker builds each tooth's BVH once.

One core: the worker asks `orthosim.cli.run.run_for_batch` for `RunOptions.on_one_core()` (the simulation in the
worker's process, no prefetch or encoder threads, ffmpeg on one thread) and runs with
`worker.WORKER_ENV` (llvmpipe on one raster thread), and writes what `orthosim run` writes.
BVH memo: `orthosim.geometry.meshquery` keeps each mesh's FCL BVH per process, by content, so the
second run of a model builds none and gives the same metrics.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh

import batch_helpers as H
from orthosim.batch import BatchOptions, parse_sweep, plan_batch, run_batch
from orthosim.batch.worker import WORKER_ENV
from orthosim.geometry import meshquery
from orthosim.runtime.options import RenderOptions, RunOptions

VOLATILE = {"wall_s", "fps", "render_fps", "case_file", "outputs"}
BARE = RunOptions(render=RenderOptions(size=(48, 32), frames_per_step=1))


@pytest.fixture(autouse=True)
def _this_pytest_worker_keeps_its_threads(monkeypatch):
    """`run_for_batch` on one core keeps its process to one thread for good (a batch worker's
    whole life); run here in the pytest worker, that must end with the test."""
    from orthosim.system import firstrun

    monkeypatch.setattr(firstrun, "_one_thread", [])


@pytest.fixture(scope="module")
def case_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("cases") / "small.toml"
    path.write_text(H.SMALL_CASE)
    return path


def stable_metrics(run_dir: Path) -> dict:
    return {k: v for k, v in json.loads((run_dir / "metrics.json").read_text()).items() if k not in VOLATILE}


def decoded_video(path: Path) -> list[bytes]:
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    next(reader)  # the stream's description
    return [bytes(frame) for frame in reader]


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_a_one_core_run_starts_no_thread_runs_ffmpeg_on_one_and_writes_what_orthosim_run_writes(case_file, tmp_path,
                                                                                                 monkeypatch):
    import imageio_ffmpeg

    from orthosim.cli.run import run_for_batch

    reference = tmp_path / "run"
    cli = [sys.executable, "-c", "from orthosim.cli import entry; entry()", "run", str(case_file), "--out", str(reference),
           "--size", "48x32", "--frames-per-step", "1", "-q"]
    done = subprocess.run(cli, capture_output=True, text=True, env={**os.environ, "PYOPENGL_PLATFORM": "osmesa"}, timeout=600)
    assert done.returncode == 0, done.stderr

    started, ffmpeg_params = [], []
    real_start, real_write_frames = threading.Thread.start, imageio_ffmpeg.write_frames
    monkeypatch.setattr(threading.Thread, "start", lambda self: (started.append(self.name), real_start(self))[1])
    monkeypatch.setattr(imageio_ffmpeg, "write_frames",
                        lambda *a, **k: (ffmpeg_params.append(k.get("output_params")), real_write_frames(*a, **k))[1])
    one_core = tmp_path / "one_core"
    record = run_for_batch(case_file, one_core, BARE.on_one_core())
    # no prefetch thread, no PNG or MP4 writer thread, no simulation child's sender; tqdm starts its
    # monitor (asleep but for a look every 10 s) with any bar, even one disabled off a terminal
    assert [name for name in started if name != "tqdm_monitor"] == []
    assert len(ffmpeg_params) == 1 and "-threads" in ffmpeg_params[0]
    assert ffmpeg_params[0][ffmpeg_params[0].index("-threads") + 1] == "1"
    assert record["options"]["render"]["single_core"] is True

    # the pipelined run (this process, threads) starts its threads: the check above can fail
    pipelined = tmp_path / "pipelined"
    run_for_batch(case_file, pipelined, replace(BARE, simulate_in_process=True))
    assert {"prefetch", "png-0", "mp4"} <= set(started)
    assert "-threads" not in ffmpeg_params[1]

    assert stable_metrics(one_core) == stable_metrics(reference)  # bit for bit
    frames = sorted((reference / "frames").glob("*.png"))
    assert len(frames) == 3
    assert [f.read_bytes() for f in frames] == [(one_core / "frames" / f.name).read_bytes() for f in frames]
    assert decoded_video(one_core / "animation.mp4") == decoded_video(reference / "animation.mp4")
    for name in ("distances.csv", "distances_per_step.csv"):
        assert (one_core / name).read_bytes() == (reference / name).read_bytes()


def test_batch_workers_render_with_one_llvmpipe_thread_and_no_python_thread_left(case_file, tmp_path):
    vs = plan_batch([case_file], sweeps=[parse_sweep("loads.0.force_cN=100,150")])
    rows = run_batch(vs, tmp_path, H.with_threads, BatchOptions(workers=1, run=H.RUN, progress=False))
    assert [r.status for r in rows] == ["ok", "ok"]
    for v in vs:
        threads = json.loads((tmp_path / v.run_id / "threads.json").read_text())
        # the raster threads llvmpipe made for the worker's GL context: LP_NUM_THREADS of them
        assert sum(name.startswith("llvmpipe") for name in threads["native"]) == int(WORKER_ENV["LP_NUM_THREADS"])
        assert [name for name in threads["python"] if name != "tqdm_monitor"] == ["MainThread"]


def _tooth(seed: int) -> trimesh.Trimesh:
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=3.0)
    mesh.vertices = mesh.vertices * (1.0 + 0.1 * np.random.default_rng(seed).random((len(mesh.vertices), 1)))
    return mesh


def test_objects_of_one_mesh_share_its_bvh_and_keep_their_own_poses():
    import gc

    meshquery.forget_bvhs()
    a, b = _tooth(1), _tooth(2)
    builds = meshquery.bvh_builds
    oa, oa2, ob = meshquery.fcl_object(a), meshquery.fcl_object(trimesh.Trimesh(a.vertices.copy(), a.faces.copy())), meshquery.fcl_object(b)
    assert meshquery.bvh_builds - builds == 2  # a's second object, of a copy of a, found a's BVH by content
    assert meshquery.bvh(a) is meshquery.bvh(a.copy()) and meshquery.bvh(a) is not meshquery.bvh(b)
    shifted = np.eye(4)
    shifted[0, 3] = 20.0
    meshquery.set_pose(oa, np.eye(4))
    meshquery.set_pose(oa2, shifted)
    meshquery.set_pose(ob, shifted)
    assert meshquery.distance(oa, oa2) > 10.0  # the two objects of one BVH are in two places
    assert meshquery.collide(oa2, ob)[0] and not meshquery.collide(oa, ob)[0]
    del oa, oa2
    gc.collect()
    again = meshquery.fcl_object(a)  # the BVH outlives the objects that used it
    meshquery.set_pose(again, shifted)
    assert meshquery.collide(again, ob)[0] and meshquery.bvh_builds - builds == 2
    meshquery.forget_bvhs()
    gc.collect()
    meshquery.set_pose(ob, np.eye(4))  # and an object outlives the memo's hold on its BVH
    assert not meshquery.collide(again, ob)[0] and meshquery.distance(again, ob) > 10.0


def test_the_bvh_memo_keeps_the_most_recently_used_meshes_only(monkeypatch):
    monkeypatch.setattr(meshquery, "BVH_MEMO_SIZE", 3)
    meshquery.forget_bvhs()
    meshes = [_tooth(10 + i) for i in range(4)]
    for m in meshes[:3]:
        meshquery.bvh(m)
    meshquery.bvh(meshes[0])  # used again: the least recently used is now meshes[1]
    builds = meshquery.bvh_builds
    meshquery.bvh(meshes[3])
    assert len(meshquery._BVHS) == 3 and meshquery.bvh_builds == builds + 1
    meshquery.bvh(meshes[0])
    meshquery.bvh(meshes[2])
    assert meshquery.bvh_builds == builds + 1  # kept
    meshquery.bvh(meshes[1])
    assert meshquery.bvh_builds == builds + 2  # dropped, built again
    meshquery.forget_bvhs()


def test_a_throw_away_mesh_stays_out_of_the_bvh_memo_and_pushes_no_tooth_out(monkeypatch):
    # the exact queries' patches (a few faces of a tooth near another) are built afresh each time
    monkeypatch.setattr(meshquery, "BVH_MEMO_SIZE", 2)
    meshquery.forget_bvhs()
    teeth = [_tooth(20), _tooth(21)]
    for m in teeth:
        meshquery.bvh(m)
    builds = meshquery.bvh_builds
    patch = trimesh.Trimesh(teeth[0].vertices, teeth[0].faces[:40])
    obj = meshquery.fcl_object(patch, memo=False)
    whole = meshquery.fcl_object(teeth[1])
    assert meshquery.collide(obj, whole)[0]  # the patch's BVH is whole and usable
    assert len(meshquery._BVHS) == 2 and meshquery.bvh_builds == builds
    meshquery.bvh(teeth[0])
    assert meshquery.bvh_builds == builds  # both teeth still in the memo
    meshquery.forget_bvhs()


def test_the_second_run_of_a_model_builds_no_bvh_and_gives_the_same_metrics(case_file, tmp_path):
    from orthosim.cli.run import run_for_batch

    meshquery.forget_bvhs()
    before = meshquery.bvh_builds
    run_for_batch(case_file, tmp_path / "first", RunOptions(render=None))
    first = meshquery.bvh_builds - before
    assert first > 0
    run_for_batch(case_file, tmp_path / "second", RunOptions(render=None))
    assert meshquery.bvh_builds - before == first  # none built for the second run
    assert stable_metrics(tmp_path / "second") == stable_metrics(tmp_path / "first")
    # and the same as a process that built every BVH itself
    fresh = tmp_path / "fresh"
    done = subprocess.run([sys.executable, "-c", "from orthosim.cli import entry; entry()", "run", str(case_file), "--out",
                           str(fresh), "--no-render", "-q"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert stable_metrics(tmp_path / "second") == stable_metrics(fresh)


def test_a_one_core_render_writes_the_pipelined_files_and_a_failed_one_leaves_none(tmp_path):
    from orthosim import OrthosimError
    from orthosim_render.animation import render_run
    from orthosim_bench.render import SyntheticMotion
    from orthosim_render.frame_state import FrameState
    from orthosim_render.standin import standin_dentition

    dentition = standin_dentition()
    motion = SyntheticMotion(dentition, n_markers=50)
    states = [motion(i) for i in range(4)]
    options = RenderOptions(views=("frontal", "maxillary"), size=(80, 60), gif=True, split_views=True)
    render_run(dentition, states, tmp_path / "pipelined", options, progress=False)
    render_run(dentition, iter(states), tmp_path / "one_core", replace(options, single_core=True), progress=False)
    files = sorted(p.relative_to(tmp_path / "pipelined") for p in (tmp_path / "pipelined").rglob("*") if p.is_file())
    assert len([f for f in files if f.suffix == ".png"]) == 12  # 4 tiled frames, 4 per view
    assert files == sorted(p.relative_to(tmp_path / "one_core") for p in (tmp_path / "one_core").rglob("*") if p.is_file())
    for f in files:
        a, b = tmp_path / "pipelined" / f, tmp_path / "one_core" / f
        if f.suffix == ".mp4":
            assert decoded_video(a) == decoded_video(b)
        else:
            assert a.read_bytes() == b.read_bytes(), f

    def failing():
        yield FrameState.rest(dentition)
        yield FrameState.rest(dentition)
        raise OrthosimError("case.toml", "loads", "cannot continue")

    with pytest.raises(OrthosimError):
        render_run(dentition, failing(), tmp_path / "failed", RenderOptions(size=(80, 60), single_core=True), progress=False)
    assert not (tmp_path / "failed" / "animation.mp4").exists()
    assert not [p for p in (tmp_path / "failed").rglob(".*")]  # no temporary file either
