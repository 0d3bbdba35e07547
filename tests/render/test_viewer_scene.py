"""animation.glb: a treatment as one animated glTF scene that any glTF tool plays.

Held here: every keyframe's node transforms are the step's poses in metres (to float32 precision),
the tooth meshes are the model's own (no larger), an extracted tooth is scaled out from its day, a
moving tooth shows in the moving tint, one contact marker per touching pair sits at the contact and
shows only where the pair touches; the scene is y up, +z anterior, in metres; the Khronos validator
finds 0 errors in the GLB of each shipped kind of case (parametric, Open-Full-Jaw, labelled scan);
`orthosim run` writes the pair beside its frames and `--no-animation` leaves it out.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from cli_helpers import orthosim
from render_helpers import case3_run
from gltf_validator_helpers import errors_of, validate_glb
from orthosim_render.gltf import quaternion_xyzw, read_glb, rotation_of_quaternion
from orthosim_render.treatment_gltf import (CONTACT_MARKER_RADIUS_MM, MM, ContactMarker, SceneKeyframe,
                                            ContactLocator, treatment_glb)

ROOT = Path(__file__).resolve().parents[2]
CASE3 = ROOT / "cases" / "case3_incisor_space_closure.toml"
FLOAT32_MM = 1e-4  # float32 metres of an arch-sized scene: ~4e-9 m; rotations ~1e-7


@pytest.fixture(scope="module")
def dentition():
    from orthosim.exchange.case import load_case

    return load_case(ROOT / "cases" / "normal_occlusion.toml").build_dentition()


def _turned(pose: np.ndarray, degrees: float, shift_mm) -> np.ndarray:
    a = np.radians(degrees)
    turn = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    out = pose.copy()
    out[:3, :3] = turn @ pose[:3, :3]
    out[:3, 3] += shift_mm
    return out


@pytest.fixture(scope="module")
def keyframes(dentition):
    """Three keyframes: rest; 13 turned and shifted, 14 gone, a contact 11-21; 13 further, no contact."""
    rest = dentition.rest_poses()
    second = {**rest, 13: _turned(rest[13], 5.0, [0.5, 0.0, -0.3])}
    third = {**rest, 13: _turned(rest[13], 12.0, [1.0, 0.2, -0.6])}
    centre = tuple((rest[11][:3, 3] + rest[21][:3, 3]) / 2)
    return [SceneKeyframe(0, 0.0, rest),
            SceneKeyframe(1, 14.0, second, frozenset({14}), frozenset({13}), (ContactMarker((11, 21), centre),)),
            SceneKeyframe(2, 28.0, third, frozenset({14}), frozenset({13}))]


@pytest.fixture(scope="module")
def scene(dentition, keyframes):
    return read_glb(treatment_glb(dentition, keyframes, title="test"))


def _node(scene, name: str) -> tuple[int, dict]:
    return next((i, n) for i, n in enumerate(scene.doc["nodes"]) if n["name"] == name)


def _sampled(scene, node: int, path: str) -> np.ndarray | None:
    """The keyframe values of `path` ("translation", "rotation", "scale") of `node`, or None when not animated."""
    animation = scene.doc["animations"][0]
    for c in animation["channels"]:
        if c["target"] == {"node": node, "path": path}:
            return scene.array(animation["samplers"][c["sampler"]]["output"])
    return None


def node_poses_mm(scene, fdi: int) -> np.ndarray:
    """(k, 4, 4) the tooth node's transform at each keyframe, back in millimetres."""
    i, _ = _node(scene, f"tooth_{fdi}")
    t = _sampled(scene, i, "translation").astype(float) / MM
    R = rotation_of_quaternion(_sampled(scene, i, "rotation"))
    out = np.tile(np.eye(4), (len(t), 1, 1))
    out[:, :3, :3], out[:, :3, 3] = R, t
    return out


def test_each_keyframes_node_transform_is_the_steps_pose_in_metres(dentition, keyframes, scene):
    for n in dentition.fdis:
        poses = node_poses_mm(scene, n)
        for k, frame in enumerate(keyframes):
            want = frame.poses[n]
            assert np.abs(poses[k][:3, 3] - want[:3, 3]).max() < FLOAT32_MM
            assert np.abs(poses[k][:3, :3] - want[:3, :3]).max() < 1e-6


def test_the_tooth_meshes_are_the_models_own_in_metres_in_the_tooths_frame(dentition, scene):
    for n in (11, 16, 36):
        _, node = _node(scene, f"tooth_{n}_still")
        mesh = scene.doc["meshes"][node["mesh"]]
        positions = scene.array(mesh["primitives"][0]["attributes"]["POSITION"])
        faces = sum(scene.doc["accessors"][p["indices"]]["count"] // 3 for p in mesh["primitives"])
        model = dentition.teeth[n].mesh
        assert len(positions) == len(model.vertices) and faces == len(model.faces)
        assert np.abs(positions / MM - model.vertices).max() < FLOAT32_MM
        assert {p["extras"]["part"] for p in mesh["primitives"]} == {"crown", "root"}


def test_an_extracted_tooth_is_scaled_out_from_its_day_and_a_moving_tooth_shows_tinted(scene):
    i, _ = _node(scene, "tooth_14")
    assert _sampled(scene, i, "scale")[:, 0].tolist() == [1.0, 0.0, 0.0]
    still, _ = _node(scene, "tooth_13_still")
    tinted, node = _node(scene, "tooth_13_moving")
    assert _sampled(scene, still, "scale")[:, 0].tolist() == [1.0, 0.0, 0.0]
    assert _sampled(scene, tinted, "scale")[:, 0].tolist() == [0.0, 1.0, 1.0]
    material = scene.doc["materials"][scene.doc["meshes"][node["mesh"]]["primitives"][0]["material"]]
    assert material["name"] == "crown moving"
    samplers = {c["target"]["path"]: scene.doc["animations"][0]["samplers"][c["sampler"]]["interpolation"]
                for c in scene.doc["animations"][0]["channels"] if c["target"]["node"] == tinted}
    assert samplers == {"scale": "STEP"}


def test_one_marker_per_touching_pair_at_its_contact_shown_only_where_it_touches(dentition, keyframes, scene):
    markers = [n for n in scene.doc["nodes"] if n.get("extras", {}).get("role") == "contact"]
    assert [m["name"] for m in markers] == ["contact_11_21"]
    i, _ = _node(scene, "contact_11_21")
    scale = _sampled(scene, i, "scale")[:, 0]
    assert np.allclose(scale, [0.0, CONTACT_MARKER_RADIUS_MM * MM, 0.0])
    at = _sampled(scene, i, "translation")[1] / MM
    assert np.abs(at - keyframes[1].contacts[0].center_mm).max() < FLOAT32_MM


def test_the_scene_is_y_up_with_the_incisors_to_the_front_in_metres(dentition, scene):
    """glTF: metres, +Y up, the front facing +Z: the upper crowns hang down, incisors lie in front of the molars."""
    poses = {n: node_poses_mm(scene, n)[0] * np.array([1, 1, 1, MM]) for n in (11, 16, 31)}
    assert poses[11][2, 3] > poses[16][2, 3] + 0.02  # 11 at least 20 mm in front of 16 (metres)
    assert poses[11][1, 3] > poses[31][1, 3]  # the upper CEJ above the lower
    width = abs(poses[16][0, 3] - node_poses_mm(scene, 26)[0][0, 3] * MM)
    assert 0.03 < width < 0.07  # an arch is a few centimetres wide: metres, not millimetres
    extras = scene.doc["scenes"][0]["extras"]["orthosim"]
    assert extras["steps"] == [0, 1, 2] and extras["days"] == [0.0, 14.0, 28.0]
    assert set(extras["views"]) == {"frontal", "right_buccal", "left_buccal", "maxillary_occlusal", "mandibular_occlusal"}


def test_quaternions_round_trip_rotations_of_every_kind():
    rng = np.random.default_rng(7)
    q = rng.normal(size=(200, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    R = rotation_of_quaternion(q)
    R = np.concatenate([R, np.diag([1.0, -1, -1])[None], np.diag([-1.0, 1, -1])[None], np.diag([-1.0, -1, 1])[None]])
    assert np.abs(rotation_of_quaternion(quaternion_xyzw(R)) - R).max() < 1e-12


# ------------------------------------------------------------------------------------------ real runs
@pytest.fixture(scope="module")
def case3(tmp_path_factory):
    """Case 3 run by `orthosim run` (frames, animation.glb, viewer.html), and its step records."""
    out, _, records, _ = case3_run(tmp_path_factory.mktemp("case3"))
    return out, records


@pytest.mark.slow  # an end-to-end run in a child process
def test_orthosim_run_writes_the_scene_whose_keyframes_are_the_step_records_poses(case3):
    out, records = case3
    run = json.loads((out / "run.json").read_text())
    assert run["render"]["outputs"]["glb"] == "animation.glb" and run["render"]["outputs"]["viewer"] == "viewer.html"
    scene = read_glb((out / "animation.glb").read_bytes())
    assert scene.doc["scenes"][0]["extras"]["orthosim"]["steps"] == [r.step for r in records]
    for n in records[0].poses:
        poses = node_poses_mm(scene, n)
        want = np.stack([r.poses[n] for r in records])
        assert np.abs(poses[:, :3, 3] - want[:, :3, 3]).max() < FLOAT32_MM
        assert np.abs(poses[:, :3, :3] - want[:, :3, :3]).max() < 1e-6


@pytest.mark.slow  # an end-to-end run in a child process
def test_no_animation_leaves_the_scene_and_page_out(tmp_path):
    out = tmp_path / "run"
    r = orthosim("run", CASE3, "--out", out, "--frames-per-step", "1", "--size", "160x120", "--no-animation")
    assert r.returncode == 0, r.stderr
    assert (out / "animation.mp4").is_file()
    assert not (out / "animation.glb").exists() and not (out / "viewer.html").exists()


@pytest.mark.slow  # node and the validator
def test_the_validator_finds_no_error_in_a_parametric_runs_scene(case3):
    report = validate_glb(case3[0] / "animation.glb")
    assert errors_of(report) == []


@pytest.mark.slow  # a labelled scan built, its model made and the validator run
def test_the_validator_finds_no_error_in_a_labelled_scans_scene_with_its_gum(tmp_path):
    from orthosim.exchange.labelledscan import load_labelled_scans
    from orthosim.model.parametric import parametric_dentition
    from orthosim_bench.scanarch import write_labelled_arch

    model = parametric_dentition("medium")
    scans = [write_labelled_arch(model, jaw, tmp_path / "scans", "p1") for jaw in ("upper", "lower")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scanned = load_labelled_scans(*scans)
    rest = scanned.rest_poses()
    moved = {**rest, 11: _turned(rest[11], 4.0, [0.0, 0.0, -0.5])}
    frames = [SceneKeyframe(0, 0.0, rest), SceneKeyframe(1, 30.0, moved, moving=frozenset({11}))]
    path = tmp_path / "scan.glb"
    path.write_bytes(treatment_glb(scanned, frames, title="scan"))
    scene = read_glb(path.read_bytes())
    assert {n["name"] for n in scene.doc["nodes"]} >= {"gingiva_upper", "gingiva_lower"}
    assert errors_of(validate_glb(path)) == []


@pytest.mark.slow
@pytest.mark.real_data
def test_the_validator_finds_no_error_in_an_open_full_jaw_scene(tmp_path):
    from orthosim.exchange.case import load_case

    dent = load_case(ROOT / "cases" / "open_full_jaw_case1_first_premolar_extraction.toml").build_dentition()
    rest = dent.rest_poses()
    first = next(iter(rest))
    frames = [SceneKeyframe(0, 0.0, rest, frozenset({first})),
              SceneKeyframe(1, 30.0, {**rest, first: _turned(rest[first], 3.0, [0.2, 0, 0])}, frozenset({first}))]
    path = tmp_path / "ofj.glb"
    path.write_bytes(treatment_glb(dent, frames, title="open full jaw"))
    assert errors_of(validate_glb(path)) == []


def test_contacts_of_a_step_are_grouped_into_one_marker_per_pair(dentition):
    """Spheres between 11 and 21 and between 13 and 14 become two markers, each at its spheres' mean."""
    rest = dentition.rest_poses()
    a = (dentition.teeth[11].to_world(dentition.teeth[11].crown_vertices).mean(axis=0)
         + dentition.teeth[21].to_world(dentition.teeth[21].crown_vertices).mean(axis=0)) / 2
    b = (dentition.teeth[13].to_world(dentition.teeth[13].crown_vertices).mean(axis=0)
         + dentition.teeth[14].to_world(dentition.teeth[14].crown_vertices).mean(axis=0)) / 2

    def nearest_surface(point, fdi):
        world = dentition.teeth[fdi].to_world(dentition.teeth[fdi].mesh.vertices)
        return world[np.linalg.norm(world - point, axis=1).argmin()]

    spheres = np.array([nearest_surface(a, 11), nearest_surface(a, 21), nearest_surface(b, 13), nearest_surface(b, 14)])
    markers = ContactLocator(dentition).markers(rest, [(21, 11), (13, 14)], spheres)
    assert [m.pair for m in markers] == [(11, 21), (13, 14)]
    assert np.allclose(markers[0].center_mm, spheres[:2].mean(axis=0))
    assert np.allclose(markers[1].center_mm, spheres[2:].mean(axis=0))


def test_export_scene_glb_is_in_metres_with_each_tooth_at_its_pose(dentition, tmp_path):
    """`--export-scene glb` changed from millimetres to metres (README): a tooth's posed vertices
    read back by trimesh are the model's posed vertices x 0.001."""
    import trimesh
    from types import SimpleNamespace

    from orthosim.exchange.scene_export import export_scenes

    rest = dentition.rest_poses()
    poses = {**rest, 13: _turned(rest[13], 10.0, [1.0, 0.0, 0.0])}
    (path,) = export_scenes(dentition, [SimpleNamespace(step=3, poses=poses)], {14}, tmp_path, "glb")
    scene = trimesh.load(path)
    assert "tooth_14" not in scene.graph.nodes
    posed = scene.geometry["tooth_13"].copy().apply_transform(scene.graph.get("tooth_13")[0]).vertices
    want = dentition.teeth[13].to_world(dentition.teeth[13].mesh.vertices, poses[13]) * MM
    assert np.abs(posed - want).max() < 1e-9


@pytest.mark.slow  # 28 teeth simplified
def test_a_scene_over_the_size_limit_gets_simplified_teeth_that_fit_it(dentition, keyframes):
    """The models' own meshes while the scene fits; above the limit every tooth is simplified so that
    the GLB fits, its crown and root kept apart (here a limit of a third of the scene)."""
    whole = treatment_glb(dentition, keyframes, title="t")
    limit = len(whole) // 3
    data = treatment_glb(dentition, keyframes, title="t", max_bytes=limit)
    assert len(data) <= limit
    small = read_glb(data)
    _, node = _node(small, "tooth_16_still")
    mesh = small.doc["meshes"][node["mesh"]]
    faces = sum(small.doc["accessors"][p["indices"]]["count"] // 3 for p in mesh["primitives"])
    assert faces < len(dentition.teeth[16].mesh.faces) / 2
    assert {p["extras"]["part"] for p in mesh["primitives"]} == {"crown", "root"}


def _children_named(scene, name: str) -> list[int]:
    return [i for i, n in enumerate(scene.doc["nodes"]) if n["name"] == name]


def test_a_tooth_whose_shape_changes_at_a_keyframe_shows_its_new_shape_from_there_on(dentition, keyframes):
    # a staging's tooth after its interproximal reduction: the cut shape from keyframe 1 on, the whole one before
    import trimesh

    whole = dentition.teeth[11]
    cut = trimesh.Trimesh(whole.mesh.vertices * [0.9, 1.0, 1.0], whole.mesh.faces, process=False)
    scene = read_glb(treatment_glb(dentition, keyframes, title="test", changed={11: (1, (cut, whole.face_part))}))
    before, after = _children_named(scene, "tooth_11_still")
    assert _sampled(scene, before, "scale")[:, 0].tolist() == [1.0, 0.0, 0.0]
    assert _sampled(scene, after, "scale")[:, 0].tolist() == [0.0, 1.0, 1.0]
    positions = scene.array(scene.doc["meshes"][scene.doc["nodes"][after]["mesh"]]["primitives"][0]["attributes"]["POSITION"])
    assert np.abs(positions / MM - cut.vertices).max() < FLOAT32_MM


@pytest.mark.slow  # the crowding case planned
def test_the_stagings_scene_shows_each_reduced_tooth_cut_as_its_stage_models_from_stage_one(tmp_path):
    from orthosim.staging.caseplan import plan_case
    from orthosim.staging.models import printable, stage_tooth_meshes
    from orthosim.staging.reduction import reduced_meshes
    from orthosim_render.viewer_page import write_staging_viewer

    run = plan_case(Path(__file__).resolve().parents[2] / "cases" / "staging_lower_incisor_crowding.toml")
    plan = run.plan
    assert plan.ipr, "the crowding case plans interproximal reduction"
    scene = read_glb(write_staging_viewer(run, tmp_path)["glb"].read_bytes())
    reduced = reduced_meshes({n: run.dentition.teeth[n].mesh for n in plan.teeth}, plan.ipr, plan.target)
    stage_one = stage_tooth_meshes(run.dentition, plan.teeth, 1, reduced)
    shown_reduced = [n for n in plan.teeth if len(_children_named(scene, f"tooth_{n}_still")) == 2]
    assert len(shown_reduced) >= 2, "each IPR contact has two teeth shown reduced"
    for n in shown_reduced:
        before, after = _children_named(scene, f"tooth_{n}_still")
        assert _sampled(scene, before, "scale")[1:, 0].max() == 0.0  # the whole tooth gone from stage 1
        positions = scene.array(scene.doc["meshes"][scene.doc["nodes"][after]["mesh"]]["primitives"][0]["attributes"]["POSITION"])
        model = printable(stage_one[n])
        assert len(positions) == len(model.vertices)
        assert np.abs(positions / MM - model.vertices).max() < FLOAT32_MM
