"""`orthosim spheretree build|eval` from the command line: the files and figures users rely on."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from orthosim.errors import SphereTreeError
from orthosim.spheretree import read_sph
from orthosim.cli.spheretree import spheretree


@pytest.fixture()
def mesh_folder(tmp_path):
    folder = tmp_path / "teeth"
    folder.mkdir()
    # Tooth-sized closed shapes named by FDI number (a capsule ~ a single-rooted tooth).
    trimesh.creation.capsule(height=14.0, radius=3.0, count=[16, 16]).export(folder / "tooth_11.stl")
    trimesh.creation.capsule(height=12.0, radius=3.5, count=[16, 16]).export(folder / "tooth_21.stl")
    return folder


def test_build_writes_one_sph_per_tooth_named_by_fdi(tmp_path, mesh_folder, monkeypatch):
    monkeypatch.setenv("ORTHOSIM_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "trees"
    res = CliRunner().invoke(spheretree, ["build", str(mesh_folder), "--method", "octree", "--depth", "4", "--out", str(out),
                                          "--numbering", "fdi"])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.iterdir()) == ["11.sph", "21.sph"]
    mesh = trimesh.load(mesh_folder / "tooth_11.stl")
    tree = read_sph(out / "11.sph", mesh.vertices, mesh.faces)
    assert tree.depth == 4 and tree.branching == 8  # an octree always splits in 8
    tree.validate(mesh.vertices, mesh.faces)
    assert any((tmp_path / "cache").glob("*.npz"))  # built through the cache


@pytest.mark.parametrize("numbering, names", [
    (None, ["tooth_11.sph", "tooth_21.sph"]),  # numbering unknown: the files' own names, no FDI claimed
    ("universal", ["23.sph", "34.sph"]),  # Universal 11 is the upper left canine, 21 the lower left first premolar
])
def test_trees_are_named_by_fdi_only_when_the_numbering_is_known(tmp_path, mesh_folder, monkeypatch, numbering, names):
    monkeypatch.setenv("ORTHOSIM_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "trees"
    args = ["build", str(mesh_folder), "--method", "octree", "--depth", "3", "--out", str(out)]
    res = CliRunner().invoke(spheretree, args + (["--numbering", numbering] if numbering else []))
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.iterdir()) == names


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_eval_json_has_the_contract_fields(tmp_path, mesh_folder):
    out = tmp_path / "eval.json"
    res = CliRunner().invoke(spheretree, ["eval", str(mesh_folder), "--method", "fit", "--depth", "3",
                                          "--samples", "20000", "--out", str(out), "--numbering", "fdi"])
    assert res.exit_code == 0, res.output
    data = json.loads(out.read_text())
    assert [t["fdi"] for t in data["teeth"]] == [11, 21]
    for t in data["teeth"]:
        assert {"fdi", "leaves", "sov_sum", "sov_union", "surface_coverage", "build_s"} <= set(t)
        assert t["surface_coverage"] == 1.0 and t["surface_samples"] >= 100_000
        assert 0 < t["sov_union"] <= t["sov_sum"] + 3 * t["sov_sum_stderr"]
    s = data["summary"]
    assert {"sov_sum_mean", "sov_sum_min", "sov_sum_max", "sov_union_mean", "surface_coverage_min"} <= set(s)
    assert s["sov_sum_min"] <= s["sov_sum_mean"] <= s["sov_sum_max"]
    assert np.isclose(s["sov_sum_mean"], np.mean([t["sov_sum"] for t in data["teeth"]]))
    values = [t["sov_sum"] for t in data["teeth"]]
    assert np.isclose(s["sov_sum_sem"], np.std(values, ddof=1) / np.sqrt(len(values)))
    assert 0 < s["sov_sum_mean_mc_stderr"] < max(t["sov_sum_stderr"] for t in data["teeth"])


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_eval_takes_both_arches_of_an_open_full_jaw_patient_named_by_universal_number(tmp_path):
    # Open-Full-Jaw names files by Universal number: tooth_3 is the upper right first molar, FDI 16,
    # and tooth_19 the lower left one, FDI 36 (not FDI 19, which does not exist)
    for arch, universal in (("maxilla", 3), ("mandible", 19)):
        folder = tmp_path / arch
        folder.mkdir()
        trimesh.creation.capsule(height=8.0, radius=4.0, count=[16, 16]).export(folder / f"tooth_{universal}.stl")
        trimesh.creation.capsule(height=9.0, radius=3.0, count=[16, 16]).export(folder / f"tooth_{universal + 1}.stl")
        (folder / f"teeth_axes_{arch}.json").write_text("{}")  # eval reads meshes as scanned: no axes needed
    out = tmp_path / "eval.json"
    res = CliRunner().invoke(spheretree, ["eval", str(tmp_path / "maxilla"), str(tmp_path / "mandible"), "--depth", "2",
                                          "--samples", "10000", "--out", str(out)])
    assert res.exit_code == 0, res.output
    data = json.loads(out.read_text())
    assert sorted((t["universal"], t["fdi"]) for t in data["teeth"]) == [(3, 16), (4, 15), (19, 36), (20, 35)]
    assert data["summary"]["teeth"] == 4 and len(data["sources"]) == 2


def test_eval_refuses_a_tooth_given_twice(tmp_path, mesh_folder):
    with pytest.raises(SphereTreeError, match="given twice"):
        spheretree.main(["eval", str(mesh_folder), str(mesh_folder), "--out", str(tmp_path / "e.json")], standalone_mode=False)


@pytest.mark.parametrize("args,text", [
    (["build", "{missing}", "--out", "{out}"], "not found"),
    (["build", "{folder}", "--method", "octree", "--branch", "4", "--out", "{out}"], "branch"),
    (["eval", "{folder}", "--surface-samples", "1000", "--out", "{out}/e.json"], "surface-samples"),
])
def test_user_errors_are_sphere_tree_errors(tmp_path, mesh_folder, args, text):
    args = [a.format(missing=tmp_path / "nope", out=tmp_path / "o", folder=mesh_folder) for a in args]
    with pytest.raises(SphereTreeError, match=text):
        spheretree.main(args, standalone_mode=False)
