"""Inputs at the edges: a case whose tooth mesh is far above what the model needs is simplified to the
case's budget with one message, and a bad budget is refused in one line before any work."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from cli_helpers import orthosim
from orthosim.exchange.case import load_case
from orthosim.errors import CaseError
from orthosim.exchange.meshload import MeshSimplifiedWarning

TEETH = (12, 11, 21, 22)


def _mesh_case(folder: Path, budget_line: str = "", dense: int = 11) -> Path:
    """A `meshes` case of four upper incisors in the arch frame (the parametric model's), tooth `dense`
    loop-subdivided twice (x16 triangles, the same tooth smoothed as a dense scan is)."""
    from orthosim.model.parametric import parametric_dentition

    model = parametric_dentition("smooth")
    teeth = folder / "teeth"
    teeth.mkdir()
    for n in TEETH:
        mesh = model.teeth[n].world_mesh()
        if n == dense:
            v, f = trimesh.remesh.subdivide_loop(mesh.vertices, mesh.faces, iterations=2)
            mesh = trimesh.Trimesh(v, f, process=False)
        mesh.export(teeth / f"tooth_{n}.stl")
    case = folder / "case.toml"
    files = "\n".join(f'"tooth_{n}.stl" = {n}' for n in TEETH)
    case.write_text(f'[case]\nname = "dense incisor"\n\n[model]\nkind = "meshes"\nfolder = "teeth"\n{budget_line}\n'
                    f'[model.files]\n{files}\n\n[treatment]\nduration_days = 4\nstep_days = 2\n'
                    'detector = "continuous"\n')
    return case


def _build(case_file: Path):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        dentition = load_case(case_file).build_dentition()
    return dentition, [str(w.message) for w in caught if issubclass(w.category, MeshSimplifiedWarning)]


def test_a_dense_tooth_in_a_case_is_simplified_to_the_case_budget_and_cached_under_it(tmp_path, monkeypatch):
    monkeypatch.setenv("ORTHOSIM_CACHE", str(tmp_path / "cache"))
    case = _mesh_case(tmp_path, "max_triangles_per_tooth = 20000")
    in_file = len(trimesh.load(tmp_path / "teeth" / "tooth_11.stl").faces)
    assert in_file > 20_000
    dentition, first = _build(case)
    assert len(first) == 1
    assert "tooth_11.stl" in first[0] and f"{in_file:,}" in first[0] and "20,000" in first[0]
    assert len(dentition.teeth[11].mesh.faces) <= 20_000
    assert dentition.teeth[11].mesh.is_watertight
    # the others are within the budget and untouched
    for n in (12, 21, 22):
        assert len(dentition.teeth[n].mesh.faces) == len(trimesh.load(tmp_path / "teeth" / f"tooth_{n}.stl").faces)
    # the simplified tooth stands where the dense one does: same crown centre and size, within hundredths of a mm
    dense = trimesh.load(tmp_path / "teeth" / "tooth_11.stl")
    world = dentition.teeth[11].world_mesh()
    np.testing.assert_allclose(world.bounds, dense.bounds, atol=0.02)
    assert world.volume == pytest.approx(dense.volume, rel=2e-3)
    # the simplified model is cached (its message replayed on a hit); a bigger budget is another model:
    # built again, the tooth kept whole
    assert load_case(case).dentition_is_cached()
    again, messages = _build(case)
    assert messages == first and np.array_equal(again.teeth[11].mesh.faces, dentition.teeth[11].mesh.faces)
    case.write_text(case.read_text().replace("max_triangles_per_tooth = 20000", "max_triangles_per_tooth = 500000"))
    dentition, messages = _build(case)
    assert messages == [] and len(dentition.teeth[11].mesh.faces) == in_file


@pytest.mark.parametrize("value,why", [("500", "at least 10,000"), ("2.5e4", "whole number"), ("true", "whole number"),
                                      ('"many"', "whole number"), ("100000000", "at most 2,000,000")])
def test_a_bad_triangle_budget_is_one_line_naming_the_field(tmp_path, value, why):
    case = _mesh_case(tmp_path, f"max_triangles_per_tooth = {value}", dense=0)
    with pytest.raises(CaseError, match=f"max_triangles_per_tooth.*{why}"):
        load_case(case)
    result = orthosim("check", case)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "max_triangles_per_tooth" in result.stderr


def test_a_triangle_budget_on_the_parametric_model_is_refused(tmp_path):
    case = tmp_path / "case.toml"
    case.write_text('[case]\nname = "x"\n\n[model]\nkind = "parametric"\nmax_triangles_per_tooth = 50000\n\n'
                    '[treatment]\nduration_days = 4\nstep_days = 2\n')
    with pytest.raises(CaseError, match="max_triangles_per_tooth.*only to mesh models"):
        load_case(case)
