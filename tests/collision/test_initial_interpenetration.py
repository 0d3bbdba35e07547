"""A model whose teeth start interpenetrating says so: a warning naming the pair and the depth, and
the run's summary line reports it (it used to say only "max penetration 0.000 mm")."""

import json

import numpy as np
import trimesh

from cli_helpers import orthosim as run, said_lines

CASE = """
[case]
name = "overlap"
[model]
kind = "meshes"
folder = "teeth"
[model.files]
"tooth_11.stl" = 11
"tooth_21.stl" = 21
[treatment]
duration_days = 10
step_days = 10
detector = "continuous"
[[loads]]
teeth = [11]
force_cN = 50
direction = "labial"
"""


def _two_incisors(folder, overlap_mm: float) -> None:
    folder.mkdir()
    for fdi, x in ((11, overlap_mm / 2 - 3.0), (21, 3.0 - overlap_mm / 2)):
        m = trimesh.creation.capsule(height=14.0, radius=3.0, count=[16, 16])  # a single-rooted tooth's size
        m.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
        m.apply_translation([x, -8.0, 20.0])
        m.export(folder / f"tooth_{fdi}.stl")


def test_teeth_interpenetrating_at_the_start_are_named_with_their_depth_in_a_warning_and_the_summary(tmp_path):
    _two_incisors(tmp_path / "teeth", overlap_mm=1.0)
    (tmp_path / "case.toml").write_text(CASE)
    r = run("run", tmp_path / "case.toml", "--out", tmp_path / "o", "--no-render")
    assert r.returncode == 0, r.stderr
    (warning,) = said_lines(r.stderr)
    assert warning.startswith("orthosim: warning: ") and "interpenetrate at the start" in warning
    assert "11 and 21 by 0.9" in warning  # about the 1 mm the capsules overlap (facets cut a little)
    assert "beyond the 0.9" in r.stdout and "teeth 11-21" in r.stdout
    metrics = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert metrics["initial_interpenetration"][0]["pair"] == [11, 21]
    assert 0.9 < metrics["initial_interpenetration"][0]["mm"] <= 1.0


def test_two_teeth_at_the_same_place_warn_with_the_pair_and_a_real_depth_and_the_summary_reports_it(tmp_path):
    _two_incisors(tmp_path / "teeth", overlap_mm=6.0)  # both capsules at x = 0: one tooth inside the other
    (tmp_path / "case.toml").write_text(CASE)
    r = run("run", tmp_path / "case.toml", "--out", tmp_path / "o", "--no-render")
    assert r.returncode == 0, r.stderr
    # every vertex of each lies on the other's surface: a vertex-based depth reads 0 here; the
    # largest ball inside both is about the capsules' radius, 3 mm
    (warning,) = said_lines(r.stderr)
    assert "interpenetrate at the start" in warning and "11 and 21 by 2.9" in warning
    assert "max penetration" in r.stdout and "beyond the 2.9" in r.stdout and "teeth 11-21" in r.stdout
    metrics = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert metrics["initial_interpenetration"][0]["pair"] == [11, 21]
    assert 2.8 < metrics["initial_interpenetration"][0]["mm"] <= 3.0
