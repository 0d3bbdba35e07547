"""Labelled intraoral scans: crowns split by label get estimated roots, the gum is kept apart, bad label files are refused.

The scans are made at test time from the parametric model (`orthosim_bench.scanarch`: each crown
cut at its CEJ, a gum collar under it, a Teeth3DS-style JSON beside the OBJ), so the true roots
are known and nothing derived from real data is stored.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from cli_helpers import orthosim
from orthosim.errors import MeshError
from orthosim.exchange.labelledscan import load_labelled_scans, read_labelled_scan, split_scan
from orthosim.model.rootsynthesis import boundary_loops, synthesize_root
from orthosim.mechanics.resistance import center_of_resistance
from orthosim_bench.scanarch import crown_at_cej, write_labelled_arch


@pytest.fixture(scope="module")
def model():
    from orthosim.model.parametric import parametric_dentition

    return parametric_dentition("medium")


@pytest.fixture(scope="module")
def scans(model, tmp_path_factory):
    folder = tmp_path_factory.mktemp("scans")
    return write_labelled_arch(model, "upper", folder, "p1"), write_labelled_arch(model, "lower", folder, "p1")


@pytest.fixture(scope="module")
def scanned(scans):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_labelled_scans(*scans)


def test_every_labelled_tooth_becomes_a_closed_tooth_with_an_estimated_root(model, scanned):
    assert set(scanned.teeth) == set(model.teeth)
    for tooth in scanned.teeth.values():
        assert tooth.root_origin == "estimated" and tooth.root_kind == "estimated"
        assert tooth.mesh.is_watertight and tooth.mesh.is_winding_consistent and tooth.mesh.volume > 0
        assert (tooth.face_part == 1).any()  # it has root faces below its CEJ


def test_the_gum_is_its_own_mesh_and_never_enters_the_collision_model(scanned):
    from orthosim.collision.model import CollisionModel

    assert set(scanned.gingiva) == {"upper", "lower"}
    assert all(len(g.faces) > 100 for g in scanned.gingiva.values())
    collision = CollisionModel.from_dentition(scanned)
    assert sorted(collision.keys) == sorted(scanned.teeth)


def test_the_scanned_bite_is_kept_between_the_arches(model, scanned):
    """One rigid transform for both scans: every scanned crown point lands exactly where that transform puts it."""
    from scipy.spatial import cKDTree

    move = np.asarray(scanned.info["scan_to_arch"])
    assert np.allclose(move[:3, :3] @ move[:3, :3].T, np.eye(3), atol=1e-9)  # rigid: no scale, no mirror
    assert np.linalg.det(move[:3, :3]) == pytest.approx(1.0)
    for n in (11, 16, 23, 36, 41, 47):
        scanned_points = scanned.teeth[n].world_mesh().vertices
        crown = crown_at_cej(model.teeth[n]).vertices @ move[:3, :3].T + move[:3, 3]
        gap, _ = cKDTree(scanned_points).query(crown)
        assert gap.max() < 1e-6, n


def test_an_estimated_root_puts_the_centre_of_resistance_near_the_parametric_one(model, scanned):
    for n, truth in model.teeth.items():
        est = scanned.teeth[n]
        assert abs(est.root_length - truth.root_length) < 1.5
        cr_true = truth.to_world(center_of_resistance(truth))
        cr_est = est.to_world(center_of_resistance(est))
        move = scanned.info["scan_to_arch"]
        cr_true = np.asarray(move)[:3, :3] @ cr_true + np.asarray(move)[:3, 3]  # model frame -> refitted arch frame
        assert np.linalg.norm(cr_est - cr_true) < 1.5, n


def test_a_molar_crown_gets_as_many_roots_as_its_type(model):
    crown = crown_at_cej(model.teeth[36])
    rooted = synthesize_root(crown, 36, "36", labial=model.teeth[36].rest_pose[:3, 2])
    assert rooted.roots == 2 and rooted.mesh.is_watertight
    assert boundary_loops(rooted.mesh) == []
    crown = crown_at_cej(model.teeth[16])
    assert synthesize_root(crown, 16, "16", labial=model.teeth[16].rest_pose[:3, 2]).roots == 3


def _edit_labels(path: Path, edit) -> None:
    labels_path = path.with_suffix(".json")
    data = json.loads(labels_path.read_text())
    edit(data)
    labels_path.write_text(json.dumps(data))


def _spoiled_case(tmp_path, scans, edit) -> Path:
    folder = tmp_path / "scans"
    folder.mkdir()
    for scan in scans:
        for p in (scan, scan.with_suffix(".json")):
            (folder / p.name).write_bytes(p.read_bytes())
    _edit_labels(folder / scans[0].name, edit)
    case = tmp_path / "case.toml"
    case.write_text(f'[case]\nname = "spoiled"\n\n[model]\nkind = "labelled-scan"\nupper = "scans/{scans[0].name}"\n'
                    f'lower = "scans/{scans[1].name}"\n\n[treatment]\nduration_days = 2\nstep_days = 1\n')
    return case


def _relabel(old: int, new: int):
    def edit(data):
        data["labels"] = [new if v == old else v for v in data["labels"]]
    return edit


def _few(data):
    labels = data["labels"]
    gum = [i for i, v in enumerate(labels) if v == 0][:40]
    for i in gum:
        labels[i] = 18


BAD = {
    "length": (lambda d: d["labels"].pop(), "labels: holds .* values for the .* vertices"),
    "other jaw's FDI": (_relabel(11, 31), "labels: holds 31, not FDI numbers of the upper jaw"),
    "too few vertices": (_few, "labels: tooth 18 has only 40 vertices"),
    "several pieces": (_relabel(26, 16), "labels: tooth 16's crown is in 2 separate pieces"),
    "other jaw": (lambda d: d.update(jaw="lower"), "jaw: is 'lower' but the file is given as the upper scan"),
}


@pytest.mark.parametrize("name", list(BAD))
def test_a_bad_label_file_is_refused_in_one_line_naming_file_and_field_and_nothing_is_written(tmp_path, scans, name):
    edit, message = BAD[name]
    case = _spoiled_case(tmp_path, scans, edit)
    out = tmp_path / "out"
    result = orthosim("run", case, "--out", out, "--no-render")
    assert result.returncode == 2, result.stderr
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in result.stderr
    assert "p1_upper.json" in lines[0] and "fix:" in lines[0]
    import re

    assert re.search(message, lines[0]), lines[0]
    assert not out.exists() or not any(out.iterdir())


def test_a_mesh_and_labels_that_disagree_are_refused_before_the_split(scans, tmp_path):
    mesh = tmp_path / "x_upper.obj"
    mesh.write_bytes(scans[0].read_bytes())
    data = json.loads(scans[0].with_suffix(".json").read_text())
    data["labels"] = data["labels"][:-3]
    mesh.with_suffix(".json").write_text(json.dumps(data))
    with pytest.raises(MeshError, match="labels: holds"):
        read_labelled_scan(mesh, "upper")


def test_each_label_becomes_one_crown_open_at_exactly_one_margin(scans):
    scan = read_labelled_scan(scans[0], "upper")
    crowns, gum = split_scan(scan)
    assert set(crowns) == {11, 12, 13, 14, 15, 16, 17, 21, 22, 23, 24, 25, 26, 27}
    assert all(len(boundary_loops(c)) == 1 for c in crowns.values())


def _capped(crown):
    """The open crown closed flat across its margin (a crown exported as a solid, still without a root)."""
    import trimesh

    loop = boundary_loops(crown)[0]
    centre = len(crown.vertices)
    cap = np.column_stack([np.roll(loop, -1), loop, np.full(len(loop), centre)])
    return trimesh.Trimesh(np.vstack([crown.vertices, crown.vertices[loop].mean(axis=0)]), np.vstack([crown.faces, cap]),
                           process=False)


@pytest.mark.parametrize("frame", ["arch", "scan"])
def test_a_folder_of_crowns_loads_with_estimated_roots_beside_whole_teeth(model, tmp_path, frame):
    from orthosim.exchange.meshfolder import load_mesh_folder
    from orthosim.model.rootsynthesis import RootEstimatedWarning

    whole = (12, 22)
    for n in (13, 12, 11, 21, 22, 23, 16, 26):
        mesh = model.teeth[n].world_mesh() if n in whole else crown_at_cej(model.teeth[n])
        if n == 16 and frame == "arch":
            mesh = _capped(mesh)  # closed, but no root: taken as a crown in the arch frame
        mesh.export(tmp_path / f"tooth_{n}.stl")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        dent = load_mesh_folder(tmp_path, frame=frame)
    estimated = {n for n, t in dent.teeth.items() if t.root_origin == "estimated"}
    assert estimated == {13, 11, 21, 23, 16, 26}
    announced = [str(w.message) for w in caught if issubclass(w.category, RootEstimatedWarning)]
    assert len(announced) == 6 and all("estimated root" in m for m in announced)
    for n in estimated:
        assert dent.teeth[n].mesh.is_watertight
        assert abs(dent.teeth[n].root_length - model.teeth[n].root_length) < 1.5


def test_an_open_mesh_is_still_refused_where_crowns_are_not_asked_for(model, tmp_path):
    from orthosim.exchange.meshload import load_tooth_mesh

    crown_at_cej(model.teeth[11]).export(tmp_path / "tooth_11.stl")
    with pytest.raises(MeshError, match="not watertight"):
        load_tooth_mesh(tmp_path / "tooth_11.stl")


def test_a_run_on_labelled_scans_marks_every_root_estimated_and_exports_the_gum(tmp_path):
    """`orthosim run` end to end on a small two-arch scan (front teeth, coarse): metrics and scene."""
    from orthosim.model.parametric import parametric_dentition

    front = {13, 12, 11, 21, 22, 23, 43, 42, 41, 31, 32, 33}
    coarse = parametric_dentition("coarse")
    upper = write_labelled_arch(coarse, "upper", tmp_path, "front", subdivisions=1, teeth=front)
    lower = write_labelled_arch(coarse, "lower", tmp_path, "front", subdivisions=1, teeth=front)
    case = tmp_path / "case.toml"
    case.write_text(f'[case]\nname = "front"\n\n[model]\nkind = "labelled-scan"\nupper = "{upper.name}"\n'
                    f'lower = "{lower.name}"\n\n[treatment]\nduration_days = 4\nstep_days = 2\n\n'
                    '[[loads]]\nteeth = [13]\nforce_cN = 100\ndirection = "distal"\n')
    out = tmp_path / "out"
    result = orthosim("run", case, "--out", out, "--no-render", "--export-scene", "glb", "-q")
    assert result.returncode == 0, result.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert {n: t["root"] for n, t in metrics["teeth"].items()} == {str(n): "estimated" for n in front}
    import jsonschema
    from importlib import resources

    jsonschema.validate(metrics, json.loads(resources.files("orthosim").joinpath("schema/metrics.schema.json").read_text()))
    import trimesh

    scene = trimesh.load(next((out / "scene").glob("*.glb")))
    assert {"gingiva_upper", "gingiva_lower"} <= set(scene.graph.nodes)


@pytest.mark.parametrize("model_lines,message", [
    ('kind = "labelled-scan"\n', "model.upper: no scan given"),
    ('kind = "labelled-scan"\nupper = "nowhere_upper.obj"\n', "model.upper: no such scan file"),
    ('kind = "labelled-scan"\nupper = "p1_upper.obj"\nfolder = "x"\n', "model.folder: not used by labelled scans"),
    ('kind = "meshes"\nfolder = "."\nupper = "p1_upper.obj"\n', "model.upper: applies only to kind"),
])
def test_a_labelled_scan_model_section_is_checked_field_by_field(tmp_path, scans, model_lines, message):
    from orthosim.errors import CaseError
    from orthosim.exchange.case import load_case

    for p in (scans[0], scans[0].with_suffix(".json")):
        (tmp_path / p.name).write_bytes(p.read_bytes())
    case = tmp_path / "case.toml"
    case.write_text(f"[model]\n{model_lines}\n[treatment]\nduration_days = 2\n")
    with pytest.raises(CaseError, match=message):
        load_case(case)


def test_a_labelled_scan_case_names_the_labelled_teeth_without_loading_the_meshes(tmp_path, scans):
    from orthosim.exchange.case import load_case

    for p in (*scans, *(s.with_suffix(".json") for s in scans)):
        (tmp_path / p.name).write_bytes(p.read_bytes())
    case = tmp_path / "case.toml"
    case.write_text('[model]\nkind = "labelled-scan"\nupper = "p1_upper.obj"\nlower = "p1_lower.obj"\n\n'
                    '[treatment]\nextractions = [14, 34]\nduration_days = 2\n')
    loaded = load_case(case)
    assert loaded.model.present_teeth() == {10 * q + p for q in (1, 2, 3, 4) for p in range(1, 8)}
    assert loaded.extractions == (14, 34)


def test_a_crown_with_a_scan_hole_still_closes_into_one_solid(model):
    crown = crown_at_cej(model.teeth[21])
    top = int(np.argmax(crown.vertices @ model.teeth[21].rest_pose[:3, 1]))
    crown.update_faces(~np.isin(crown.faces, [top]).any(axis=1))  # a hole at the incisal edge
    crown.remove_unreferenced_vertices()
    assert len(boundary_loops(crown)) == 2
    rooted = synthesize_root(crown, 21, "21", labial=model.teeth[21].rest_pose[:3, 2])
    assert rooted.mesh.is_watertight and rooted.mesh.volume > 0


@pytest.mark.parametrize("suffix", [".ply", ".stl"])
def test_ply_and_stl_scans_load_like_obj(tmp_path, suffix):
    """PLY keeps shared vertices like OBJ; an STL lists every triangle's corners, and its labels follow them."""
    from orthosim.model.parametric import parametric_dentition

    coarse = parametric_dentition("coarse")
    front = {13, 12, 11, 21, 22, 23}
    path = write_labelled_arch(coarse, "upper", tmp_path, "f", subdivisions=1, suffix=suffix, teeth=front)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dent = load_labelled_scans(path, None)
    assert set(dent.teeth) == front and set(dent.gingiva) == {"upper"}
    assert all(t.mesh.is_watertight and t.root_origin == "estimated" for t in dent.teeth.values())
