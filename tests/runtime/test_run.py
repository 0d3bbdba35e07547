"""A run's outputs as a user compares and reuses them: metrics that repeat byte for byte, a schema
that gives every number its unit, the per-step distance table, the exported scene, the animation's
length and views, and options refused before any work."""

import json
import re
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from orthosim.runtime.options import RenderOptions, RunOptions
from orthosim.runtime.run import frames_per_step, run_one
from cli_helpers import orthosim

ROOT = Path(__file__).resolve().parents[2]
UNIT_SUFFIXES = ("_mm", "_deg", "_days", "_cN", "_cNmm", "_J", "_mm_per_day", "_rad_per_day", "_g_mm_per_day", "_mm2")


@pytest.fixture(scope="module")
def short_case(tmp_path_factory):
    """The paper's case 1 cut to three steps (same model, loads and detector)."""
    text = (ROOT / "cases" / "case1_first_premolar_extraction.toml").read_text()
    text, n = re.subn(r"(?m)^duration_days = \d+", "duration_days = 90", text)  # three monthly steps
    assert n == 1
    path = tmp_path_factory.mktemp("case") / "case1_short.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def two_runs(short_case, tmp_path_factory):
    out = tmp_path_factory.mktemp("runs")
    records = [run_one(short_case, out / name, RunOptions(render=None, export_scene="glb", verbosity=0))
               for name in ("a", "b")]
    return out / "a", out / "b", records


def test_the_same_case_gives_byte_identical_metrics_and_timings_only_in_run_json(two_runs):
    a, b, records = two_runs
    assert (a / "metrics.json").read_bytes() == (b / "metrics.json").read_bytes()
    assert (a / "distances_per_step.csv").read_bytes() == (b / "distances_per_step.csv").read_bytes()
    text = (a / "metrics.json").read_text()
    assert "wall" not in text and str(ROOT) not in text and "/tmp" not in text  # no timings, no machine paths
    run = json.loads((a / "run.json").read_text())
    assert run["complete"] is True and run["timings_s"]["simulate"] > 0 and run["out_dir"] == str(a.resolve())


def test_metrics_follow_the_published_schema_and_every_number_has_a_unit(two_runs):
    import jsonschema

    schema = json.loads(resources.files("orthosim").joinpath("schema/metrics.schema.json").read_text())
    metrics = json.loads((two_runs[0] / "metrics.json").read_text())
    jsonschema.validate(metrics, schema)
    from orthosim.movement.report import read_steps

    step_schema = {**schema["$defs"]["step"], "$defs": schema["$defs"]}
    steps = list(read_steps(two_runs[0]))
    assert len(steps) == metrics["steps"] + 1
    for step in steps:  # steps.jsonl, the per-step detail metrics.json names
        jsonschema.validate(step, step_schema)

    def node_for(node, key):
        props = node.get("properties", {})
        if key in props:
            return props[key]
        for pattern, sub in node.get("patternProperties", {}).items():
            return sub
        return {}

    missing = []

    def walk(value, node, path, unit_known):
        unit_known = unit_known or "unit" in node or any(path[-1].endswith(s) for s in UNIT_SUFFIXES if path)
        if isinstance(value, dict):
            for k, v in value.items():
                walk(v, node_for(node, k), path + [k], unit_known or k.endswith(UNIT_SUFFIXES))
        elif isinstance(value, list):
            for v in value:
                walk(v, node.get("items", {}), path, unit_known)
        elif isinstance(value, (int, float)) and not isinstance(value, bool) and not unit_known and path[-1] not in ("pair", "from", "to", "moving", "extracted", "touching"):
            missing.append(".".join(path))

    walk(metrics, schema, [], False)
    assert not missing, f"numbers without a unit in name or schema: {sorted(set(missing))[:10]}"
    # and the check bites: a new bare number would be caught
    metrics["settings"]["new_knob"] = 1.5
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(metrics, schema)


def test_distances_per_step_table_matches_the_per_step_series(two_runs):
    a = two_runs[0]
    metrics = json.loads((a / "metrics.json").read_text())
    rows = (a / "distances_per_step.csv").read_text().strip().splitlines()
    header = rows[0].split(",")
    assert header[:3] == ["step", "time_days", "total_distance_mm"] and "15-13_mm" in header
    assert len(rows) - 1 == metrics["steps"] + 1
    from orthosim.movement.report import read_steps

    for row, step in zip(rows[1:], read_steps(a), strict=True):
        cells = row.split(",")
        assert int(cells[0]) == step["step"]
        assert float(cells[2]) == pytest.approx(step["total_distance_mm"], abs=1e-4)


def test_exported_glb_scene_puts_each_tooth_where_the_run_left_it(two_runs):
    import trimesh

    a, _, records = two_runs
    metrics = json.loads((a / "metrics.json").read_text())
    files = sorted((a / "scene").glob("*.glb"))
    assert [f.name for f in files] == ["step_00000.glb", f"step_{metrics['steps']:05d}.glb"]
    scene = trimesh.load(files[-1], force="scene")
    assert "tooth_14" not in scene.graph.nodes  # extracted
    T, geometry = scene.graph.get("tooth_16")
    final = np.array(metrics["teeth"]["16"]["final_pose"])
    assert np.allclose(T[:3, :3], final[:3, :3], atol=1e-5)
    assert np.allclose(T[:3, 3] * 1000.0, final[:3, 3], atol=1e-3)  # glTF's metres
    mesh = scene.geometry[geometry]
    posed = trimesh.transform_points(mesh.vertices, T) * 1000.0
    # the exported tooth, posed, has the centroid of the run's final tooth (mm)
    from orthosim import load_case

    dent = load_case(ROOT / "cases" / "case1_first_premolar_extraction.toml").build_dentition()
    expected = dent.teeth[16].world_mesh(np.array(metrics["teeth"]["16"]["final_pose"])).vertices.mean(axis=0)
    assert np.allclose(posed.mean(axis=0), expected, atol=1e-4)


def test_ply_export_writes_one_posed_tooth_per_file(short_case, tmp_path):
    import trimesh

    run_one(short_case, tmp_path / "o", RunOptions(render=None, export_scene="ply", export_steps=(0,), verbosity=0))
    files = sorted((tmp_path / "o" / "scene" / "step_00000").glob("tooth_*.ply"))
    assert len(files) == 24  # 28 teeth less four extractions
    from orthosim import load_case

    dent = load_case(short_case).build_dentition()
    mesh = trimesh.load(tmp_path / "o" / "scene" / "step_00000" / "tooth_11.ply")
    assert np.allclose(mesh.vertices.mean(axis=0), dent.teeth[11].world_mesh().vertices.mean(axis=0), atol=1e-4)


@pytest.mark.parametrize("args, expected", [
    (["--view", "sideways"], "--view: sideways: is not a camera preset"),
    (["--export-steps", "500"], "--export-steps: 500: is not a step of this case (0 to 30)"),
    (["--seconds", "3", "--frames-per-step", "2"], "--seconds both set the animation's length"),
    (["--fps", "0"], "--fps: 0: is not 1 to 120 frames per second"),
])
def test_a_bad_option_fails_at_once_with_one_line_and_no_output(tmp_path, args, expected):
    out = tmp_path / "o"
    r = orthosim("run", "cases/normal_occlusion.toml", "--out", str(out), *args)
    assert r.returncode == 2, r.stderr
    assert expected in r.stderr and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not out.exists()


def test_the_default_animation_lasts_at_least_five_seconds():
    for steps in (1, 9, 30, 120, 1000):
        n = 1 + steps * frames_per_step(RenderOptions(), steps)
        assert n / 30 >= 5.0
    assert frames_per_step(RenderOptions(seconds=10, fps=24), 9) == 27  # 1 + 9 * 27 = 244 frames >= 240
    assert frames_per_step(RenderOptions(frames_per_step=3), 9) == 3


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_a_drawn_run_has_the_asked_length_split_views_and_a_full_size_gif(short_case, tmp_path):
    import imageio_ffmpeg
    from PIL import Image

    out = tmp_path / "o"
    r = orthosim("run", str(short_case), "--out", str(out), "--size", "96x64", "--view", "frontal", "--view", "right",
                 "--seconds", "2", "--fps", "10", "--split-views", "--gif", "--detector", "discrete")
    assert r.returncode == 0, r.stderr
    steps = 3
    n = 1 + steps * frames_per_step(RenderOptions(seconds=2, fps=10), steps)
    assert len(list((out / "frames").glob("*.png"))) == n
    for view in ("frontal", "right_buccal"):
        pngs = sorted((out / "frames" / view).glob("*.png"))
        assert len(pngs) == n and Image.open(pngs[0]).size == (96, 64)
    assert Image.open(out / "frames" / "00000.png").size == (192, 64)  # two views side by side
    gif = Image.open(out / "animation.gif")
    assert gif.size == (192, 64)
    frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(out / "animation.mp4"))
    assert frames == n and seconds >= 2.0
    run = json.loads((out / "run.json").read_text())
    assert run["render"]["frames"] == n and run["render"]["video_fps"] == 10
    # not a terminal: nothing but the summary line
    assert len(r.stdout.strip().splitlines()) == 1 and r.stderr == ""


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_collide_step_queries_a_case_at_a_simulation_step():
    before = orthosim("collide", "step", "cases/case3_incisor_space_closure.toml", "--step", "0")
    after = orthosim("collide", "step", "cases/case3_incisor_space_closure.toml", "--step", "9")
    assert before.returncode == 0 and after.returncode == 0, before.stderr + after.stderr
    before, after = json.loads(before.stdout), json.loads(after.stdout)
    assert before["step"] == 0 and after["step"] == 9 and after["time_days"] == 126
    # the 2 mm diastema is open at the start and closed by the end: the central incisors meet
    assert [11, 21] not in before["touching"] and [11, 21] in after["touching"]
    late = orthosim("collide", "step", "cases/case3_incisor_space_closure.toml", "--step", "10")
    assert late.returncode == 2 and "past the case's last step (9)" in late.stderr


@pytest.mark.slow
@pytest.mark.real_data
def test_a_real_jaw_runs_metrics_follow_the_published_schema_too(tmp_path):
    """Mesh models say what they are (`model.kind`) like the parametric one: the schema holds for every kind."""
    import jsonschema

    text = (ROOT / "cases" / "open_full_jaw_case2_second_premolar_extraction.toml").read_text()
    step = re.search(r"(?m)^step_days = (\d+)", text).group(1)
    text, n = re.subn(r"(?m)^duration_days = \d+", f"duration_days = {step}", text)  # one step
    assert n == 1
    case = tmp_path / "real_one_step.toml"
    from orthosim.exchange.shareddata import shared_data_dir

    case.write_text(text.replace('"../../shared/data/', f'"{shared_data_dir().as_posix()}/'))
    run_one(case, tmp_path / "out", RunOptions(render=None, verbosity=0))
    schema = json.loads(resources.files("orthosim").joinpath("schema/metrics.schema.json").read_text())
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    jsonschema.validate(metrics, schema)
    assert metrics["model"]["kind"] == "open-full-jaw"
