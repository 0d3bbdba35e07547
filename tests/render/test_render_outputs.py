"""Files a rendered run leaves behind, the bench record other tools read, and user-facing errors."""

from __future__ import annotations

import json
import sys

import imageio.v3 as iio
import imageio_ffmpeg
import numpy as np
import pytest

from orthosim import OrthosimError
from orthosim.runtime.options import RenderOptions
from orthosim_render.animation import render_run, tile
from orthosim_bench.render import SyntheticMotion, run_bench
from orthosim_render.cameras import check_view, frame_view
from orthosim_render.frame_state import FrameState
from orthosim_render.standin import standin_dentition


@pytest.fixture(scope="module")
def dentition():
    return standin_dentition()


def test_run_writes_numbered_frames_video_and_gif(tmp_path, dentition):
    motion = SyntheticMotion(dentition, n_markers=50)
    result = render_run(dentition, [motion(i) for i in range(4)], tmp_path,
                        RenderOptions(views=("frontal", "maxillary"), size=(160, 120), gif=True), progress=False)
    assert result["frames"] == 4 and result["fps"] > 0
    frames = sorted(p.name for p in (tmp_path / "frames").iterdir())
    assert frames == ["00000.png", "00001.png", "00002.png", "00003.png"]
    first = iio.imread(tmp_path / "frames" / "00000.png")
    assert first.shape == (120, 320, 3)  # two views side by side
    n_video, _ = imageio_ffmpeg.count_frames_and_secs(str(tmp_path / "animation.mp4"))
    assert n_video == 4
    assert (tmp_path / "animation.gif").stat().st_size > 100
    # nothing temporary left behind
    assert not [p for p in tmp_path.rglob(".*")]


def test_alpha_frames_keep_transparency(tmp_path, dentition):
    render_run(dentition, [FrameState.rest(dentition)], tmp_path, RenderOptions(size=(160, 120), alpha=True, mp4=False),
               progress=False)
    image = iio.imread(tmp_path / "frames" / "00000.png")
    assert image.shape == (120, 160, 4)
    assert image[0, 0, 3] == 0 and image[:, :, 3].max() == 255


def test_odd_image_sizes_still_make_a_video(tmp_path, dentition):
    render_run(dentition, [FrameState.rest(dentition)] * 2, tmp_path, RenderOptions(size=(161, 121), png=False), progress=False)
    assert (tmp_path / "animation.mp4").stat().st_size > 0


def test_unknown_view_is_a_one_line_user_error():
    with pytest.raises(OrthosimError) as err:
        check_view("sideways")
    message = str(err.value)
    assert "\n" not in message and "sideways" in message and "frontal" in message


def test_view_aliases_name_the_clinical_presets():
    assert check_view("maxillary") == "maxillary_occlusal"
    assert check_view("mandibular") == "mandibular_occlusal"


def test_camera_framing_contains_every_point():
    pts = np.random.default_rng(0).uniform(-30, 30, size=(500, 3))
    for name in ("frontal", "left_buccal", "mandibular_occlusal"):
        view = frame_view(name, pts, (640, 480))
        px = view.project(pts, (640, 480))
        assert px[:, 0].min() >= 0 and px[:, 0].max() <= 640
        assert px[:, 1].min() >= 0 and px[:, 1].max() <= 480


def test_tile_places_views_left_to_right():
    a = np.zeros((2, 3, 3), np.uint8)
    b = np.full((2, 3, 3), 9, np.uint8)
    t = tile([a, b])
    assert t.shape == (2, 6, 3) and t[0, 0, 0] == 0 and t[0, 5, 0] == 9


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_bench_record_follows_the_output_contract(tmp_path, dentition):
    record = run_bench(dentition=dentition, frames=6, warmup=2, memory_frames=4, variant_rounds=1,
                       size=(160, 120), n_markers=100, tree_build=False, staging=False)
    json.dumps(record)  # serialisable as is
    assert record["staging_s"] is None  # switched off here; orthosim_bench.staging is tested on its own
    assert record["spheretree_build"] is None  # switched off here; orthosim_bench.spheretree is tested on its own
    assert record["machine"]["cores"] >= 1 and record["machine"]["gl_renderer"]
    assert record["target_fps"] == 40
    fps = record["fps"]
    assert set(fps) >= {"simulation", "render", "end_to_end"}
    assert fps["render"] > 0 and fps["end_to_end"] > 0
    # no simulation plugged in: reported as missing, never as a number
    assert fps["simulation"] is None and "simulation" in record["pending"]
    assert record["simulation_step_against_continuous_interleaved"] is None
    assert record["memory_mb"]["start"] > 0 and record["memory_mb"]["end"] > 0
    cpu = record["end_to_end"]["cpu_ms_per_frame"]  # where end to end spends its CPU (Linux /proc)
    if sys.platform.startswith("linux"):
        assert cpu["main"] > 0 and cpu["total"] >= cpu["main"] + cpu.get("png", 0.0)
        # end to end against its stages: with no simulation the slower stage is rendering, and the
        # cores bound the frame rate by the run's own CPU per frame
        stages = record["end_to_end_against_stages"]
        assert stages["slower_stage_fps"] == fps["render"]
        assert stages["share_of_slower_stage"] == pytest.approx(fps["end_to_end"] / fps["render"])
        assert stages["slower_stage_with_output_fps"] == record["end_to_end_synthetic"]["fps"]
        assert stages["cpu_bound_fps"] == pytest.approx(1000 * stages["cores"] / cpu["total"])


def test_synthetic_motion_moves_only_the_moving_teeth(dentition):
    motion = SyntheticMotion(dentition, n_markers=20)
    rest = dentition.rest_poses()
    state = motion(30)
    moved = {f for f in dentition.fdis if not np.allclose(state.poses[f], rest[f])}
    assert moved == set(motion.moving) and state.n_contacts == 20


def test_prefetch_keeps_order_and_surfaces_producer_errors():
    from orthosim_render.animation import prefetch

    assert list(prefetch(iter(range(50)))) == list(range(50))

    def failing():
        yield 1
        raise OrthosimError("case.toml", "loads", "broken")

    got = []
    with pytest.raises(OrthosimError, match="broken"):
        for x in prefetch(failing()):
            got.append(x)
    assert got == [1]


def test_a_failed_run_leaves_no_partial_video(tmp_path, dentition):
    def states():
        yield FrameState.rest(dentition)
        yield FrameState.rest(dentition)
        raise OrthosimError("case.toml", "loads", "cannot continue")

    with pytest.raises(OrthosimError):
        render_run(dentition, states(), tmp_path, RenderOptions(size=(160, 120)), progress=False)
    assert not (tmp_path / "animation.mp4").exists()
    assert not [p for p in tmp_path.rglob(".*")]  # no temporary files either


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_render_run_reports_each_frame_to_its_caller_and_the_bench_times_render_run(tmp_path, dentition, monkeypatch):
    motion = SyntheticMotion(dentition, n_markers=30)
    states = [motion(i) for i in range(4)]
    seen = []
    render_run(dentition, states, tmp_path / "run", RenderOptions(size=(160, 120), png=False), progress=False,
               on_frame=lambda st, sc: seen.append((st, len(sc.markers.positions))))
    assert [s for s, _ in seen] == states and all(n > 0 for _, n in seen)

    import orthosim_render.animation

    calls = []
    real = orthosim_render.animation.render_run

    def counted(*args, **kwargs):
        calls.append(kwargs.get("caption"))
        return real(*args, **kwargs)

    monkeypatch.setattr(orthosim_render.animation, "render_run", counted)
    record = run_bench(dentition=dentition, frames=3, warmup=1, memory_frames=2, variant_rounds=1, size=(160, 120),
                       n_markers=30, tree_build=False, staging=False, startup=False, png=False)
    assert calls == [None]  # end_to_end (synthetic here) is render_run's own loop
    assert record["end_to_end_synthetic"]["fps"] > 0


def test_used_vertices_is_numpys_unique_with_its_inverse():
    from orthosim_render.scene import used_vertices

    rng = np.random.default_rng(7)
    for n, m in ((1, 1), (10, 4), (500, 300), (2000, 50)):
        faces = rng.integers(0, n, size=(m, 3))
        used, inverse = used_vertices(faces, n)
        want_used, want_inverse = np.unique(faces, return_inverse=True)
        assert np.array_equal(used, want_used)
        assert np.array_equal(inverse, want_inverse.reshape(faces.shape))
        assert np.array_equal(used[inverse], faces)
