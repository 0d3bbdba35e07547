"""Semantic goldens: a failing image check says which tooth or contact changed, by how much and which way.

Each test draws the normal occlusion (parametric teeth, 320x240, as the goldens are drawn) once as
the golden and once changed by a known amount, and holds the explanation to exactly that change:
the tooth or contact named, the shift within a pixel and 0.05 mm of what the camera's projection
gives, the dental direction, and every other tooth unchanged; one test does the same on the
patient's real teeth (`real_data`). Goldens without labels compare pixels as before; a damaged
label file is refused in one line.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cli_helpers import orthosim
from orthosim_render.explain import explain
from orthosim_render.frame_state import FrameState
from orthosim_render.imgdiff import (GoldenSidecar, ImageInputError, Tolerance, compare_images, compare_labelled,
                                     imgdiff, write_golden)
from orthosim_render.semantic_labels import labels_paths, read_labels, render_labelled, write_labels
from orthosim_render.png import encode_png

ROOT = Path(__file__).resolve().parents[2]
SIZE = (320, 240)
GL = GoldenSidecar(gl_renderer="llvmpipe (test)", mesa_version="1.0")  # both sides alike: exact mode, no GL probe


@pytest.fixture(scope="module")
def dentition():
    from orthosim import load_case

    return load_case(ROOT / "cases" / "normal_occlusion.toml").build_dentition()


def draw(dentition, state, view):
    """(image, labels, the scene) of `state` from `view`, as a golden is drawn."""
    from orthosim_render.frame import cached_renderer
    from orthosim_render.scene import DentitionScene

    scene = DentitionScene(dentition, SIZE)
    scene.update(state)
    image, labels = render_labelled(cached_renderer(SIZE), scene, view)
    return image, labels, scene


def moved(dentition, fdi: int, move_mm: np.ndarray) -> dict:
    poses = {k: v.copy() for k, v in dentition.rest_poses().items()}
    poses[fdi][:3, 3] += move_mm
    return poses


def expected_shift(scene, point: np.ndarray, move_mm: np.ndarray) -> tuple[float, float]:
    """(px, mm in the view plane) of `move_mm` applied at `point`, from the camera's own projection."""
    view = scene.current_view
    a, b = view.project(np.stack([point, point + move_mm]), SIZE)
    axis = -view.pose[:3, 2]
    return float(np.hypot(*(b - a))), float(np.linalg.norm(move_mm - (move_mm @ axis) * axis))


def test_the_label_pass_leaves_the_image_bit_identical_and_labels_every_drawn_pixel(dentition):
    from orthosim_render.frame import cached_renderer
    from orthosim_render.scene import DentitionScene

    state = FrameState.rest(dentition)
    plain = DentitionScene(dentition, SIZE)
    plain.update(state)
    image = cached_renderer(SIZE).render(plain, "frontal")
    labelled, labels, _ = draw(dentition, state, "frontal")
    assert np.array_equal(image, labelled)
    background = np.all(image == image[0, 0], axis=2)
    assert np.array_equal(labels.labels == 0, background)
    assert np.isnan(labels.depth_mm[background]).all() and np.isfinite(labels.depth_mm[~background]).all()
    assert {e.teeth[0] for e in labels.legend if e.kind == "tooth"} == set(dentition.fdis)


@pytest.mark.parametrize("view, fdi, axis, sign, word", [
    ("frontal", 41, "mesial", -1, "distally"),
    ("frontal", 13, "mesial", -1, "distally"),
    ("right_buccal", 14, "mesial", -1, "distally"),
    ("maxillary_occlusal", 23, "mesial", 1, "mesially"),
    ("right_buccal", 16, "long_axis", -1, "apically"),
    ("frontal", 11, "labial", 1, "labially"),
])
def test_a_tooth_moved_by_a_known_amount_is_named_with_that_amount_and_nothing_else(dentition, view, fdi, axis,
                                                                                     sign, word):
    rest = dentition.rest_poses()
    tooth = dentition.teeth[fdi]
    move = sign * 0.4 * (rest[fdi][:3, :3] @ getattr(tooth, axis))  # 0.4 mm along the dental axis
    golden, golden_labels, scene = draw(dentition, FrameState(poses=rest), view)
    candidate, candidate_labels, _ = draw(dentition, FrameState(poses=moved(dentition, fdi, move)), view)
    px, mm = expected_shift(scene, tooth.to_world(tooth.crown_center), move)

    found = explain(golden, golden_labels, candidate, candidate_labels)
    (change,) = found.changes
    assert change.subject == f"tooth {fdi}" and change.kind == "moved"
    assert abs(change.shift_length_px - px) < 1.0 and abs(change.shift_mm - mm) < 0.05, (found.text(), px, mm)
    assert change.direction.split(" and ")[0] == word, found.text()
    visible = sum(1 for e in golden_labels.legend if e.kind == "tooth")
    assert found.unchanged_teeth == visible - 1
    assert found.text().startswith(f"tooth {fdi} moved {change.shift_length_px:.1f} px ({change.shift_mm:.2f} mm) {word}")
    assert found.text().endswith(f"{visible - 1} other teeth unchanged")


@pytest.mark.parametrize("view, fdi", [("frontal", 41), ("right_buccal", 13), ("mandibular_occlusal", 36)])
def test_a_removed_tooth_is_named_as_gone_and_the_teeth_behind_it_are_unchanged(dentition, view, fdi):
    rest = dentition.rest_poses()
    golden, golden_labels, _ = draw(dentition, FrameState(poses=rest), view)
    candidate, candidate_labels, _ = draw(dentition, FrameState(poses=rest, extracted=frozenset({fdi})), view)
    found = explain(golden, golden_labels, candidate, candidate_labels)
    visible = sum(1 for e in golden_labels.legend if e.kind == "tooth")
    assert found.text() == f"tooth {fdi} disappeared; {visible - 1} other teeth unchanged"


def contact_between(dentition, a: int, b: int, n: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """n contact spheres (centres, radii mm) where teeth a and b meet, on the facial side so a camera sees them."""
    from scipy.spatial import cKDTree

    ta, tb = dentition.teeth[a], dentition.teeth[b]
    va, vb = ta.to_world(ta.mesh.vertices), tb.to_world(tb.mesh.vertices)
    gap, nearest = cKDTree(vb).query(va)
    i = int(gap.argmin())
    middle = (va[i] + vb[nearest[i]]) / 2 + 1.2 * (ta.rest_pose[:3, :3] @ ta.labial)
    return middle + np.random.default_rng(1).normal(scale=0.3, size=(n, 3)), np.full(n, 0.6)


@pytest.mark.parametrize("view", ["right_buccal", "frontal"])
def test_a_shifted_contact_is_named_with_its_shift_and_nothing_else(dentition, view):
    rest = dentition.rest_poses()
    centres, radii = contact_between(dentition, 13, 14)
    golden, golden_labels, scene = draw(dentition, FrameState(poses=rest, contact_centers=centres, contact_radii=radii,
                                                              contact_pairs=((14, 13),)), view)
    shift = 0.3 * scene.current_view.pose[:3, 1]  # 0.3 mm up the image, in the view plane
    candidate, candidate_labels, _ = draw(dentition, FrameState(poses=rest, contact_centers=centres + shift,
                                                                contact_radii=radii, contact_pairs=((13, 14),)), view)
    px, mm = expected_shift(scene, centres.mean(axis=0), shift)
    found = explain(golden, golden_labels, candidate, candidate_labels)
    (change,) = found.changes
    assert change.subject == "contact 13-14" and change.kind == "moved"
    assert abs(change.shift_length_px - px) < 1.0 and abs(change.shift_mm - mm) < 0.05, found.text()
    assert found.unchanged_teeth == sum(1 for e in golden_labels.legend if e.kind == "tooth")


def test_a_contact_that_grows_or_vanishes_is_named_so(dentition):
    rest = dentition.rest_poses()
    centres, radii = contact_between(dentition, 13, 14)

    def with_contact(scale):
        state = FrameState(poses=rest, contact_centers=centres, contact_radii=radii * scale, contact_pairs=((13, 14),))
        return draw(dentition, state, "right_buccal")[:2]

    golden, golden_labels = with_contact(1.0)
    grown, grown_labels = with_contact(1.4)
    assert explain(golden, golden_labels, grown, grown_labels).text().startswith("contact 13-14 grew ")
    gone, gone_labels, _ = draw(dentition, FrameState(poses=rest), "right_buccal")
    text = explain(golden, golden_labels, gone, gone_labels).text()
    assert text.startswith("contact 13-14 gone; ") and text.endswith(" other teeth unchanged") and text.count(";") == 1


def test_a_colour_only_change_is_told_from_a_move(dentition):
    rest = dentition.rest_poses()
    golden, golden_labels, _ = draw(dentition, FrameState(poses=rest), "frontal")
    tinted, tinted_labels, _ = draw(dentition, FrameState(poses=rest, moving=frozenset({21})), "frontal")
    assert explain(golden, golden_labels, tinted, tinted_labels).text() == "tooth 21 changed colour; 27 other teeth unchanged"


# ------------------------------------------------------------------------- tolerances by label
@pytest.fixture(scope="module")
def moved_13(dentition):
    rest = dentition.rest_poses()
    move = -0.4 * (rest[13][:3, :3] @ dentition.teeth[13].mesial)
    golden = draw(dentition, FrameState(poses=rest), "right_buccal")[:2]
    candidate = draw(dentition, FrameState(poses=moved(dentition, 13, move)), "right_buccal")[:2]
    return golden, candidate


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_tolerances_by_label_pass_only_the_change_they_name(moved_13):
    (g, gl), (c, cl) = moved_13

    def verdict(**tolerances):
        return compare_labelled(g, c, GL, GL, Tolerance(), ("golden", "candidate"), gl, cl, **tolerances)[0]

    assert not verdict().matched
    assert verdict(max_shift_px=2.0).matched  # it moved ~1.5 px
    assert not verdict(max_shift_px=0.5).matched
    assert verdict(ignore=[13]).matched and verdict(ignore=["tooth"]).matched
    assert not verdict(ignore=[14]).matched and not verdict(ignore=["contact", "gingiva"]).matched
    assert verdict(max_shift_px=2.0).masked_pixels > 0
    assert verdict(max_shift_px={13: 2.0}).matched and verdict(max_shift_px={"tooth": 2.0}).matched
    assert not verdict(max_shift_px={14: 2.0}).matched and not verdict(max_shift_px={"contact": 2.0}).matched


def test_a_tolerance_naming_no_label_is_refused_in_one_line(moved_13):
    (g, gl), (c, cl) = moved_13
    with pytest.raises(ImageInputError, match="'gingva' names no label"):
        compare_labelled(g, c, GL, GL, Tolerance(), ("golden", "candidate"), gl, cl, ignore=["gingva"])
    for bad in (-1.0, float("nan"), {"tooth": -2}, {"toth": 1}):
        with pytest.raises(ImageInputError, match="max_shift_px|names no label"):
            compare_labelled(g, c, GL, GL, Tolerance(), ("golden", "candidate"), gl, cl, max_shift_px=bad)


# --------------------------------------------------------------------- files and the command line
def write_pair(folder: Path, golden, candidate, with_labels=(True, True)) -> tuple[Path, Path]:
    (g, gl), (c, cl) = golden, candidate
    gp, cp = folder / "golden.png", folder / "candidate.png"
    write_golden(gp, g, GL, gl if with_labels[0] else None)
    write_golden(cp, c, GL, cl if with_labels[1] else None)
    return gp, cp


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_imgdiff_prints_what_changed_when_both_images_carry_labels(tmp_path, moved_13):
    golden, candidate = write_pair(tmp_path, *moved_13)
    r = orthosim("imgdiff", str(golden), str(candidate))
    assert r.returncode == 1, r.stderr
    verdict, changed = r.stdout.strip().splitlines()
    assert verdict.startswith("differ (exact: ")
    assert changed.startswith("what changed: tooth 13 moved ") and " distally" in changed
    assert changed.endswith(" other teeth unchanged")
    written = json.loads((tmp_path / "candidate.diff.json").read_text())
    assert written["text"] == changed.removeprefix("what changed: ") and written["changes"][0]["subject"] == "tooth 13"
    r = orthosim("imgdiff", str(golden), str(candidate), "--max-shift-px", "2")
    assert r.returncode == 0 and "pixels left out by label" in r.stdout


def test_imgdiff_refuses_a_tolerance_naming_no_label_in_one_line(tmp_path, moved_13):
    golden, candidate = write_pair(tmp_path, *moved_13)
    r = orthosim("imgdiff", str(golden), str(candidate), "--ignore", "gingva")
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().splitlines() == [
        "orthosim: error: ignore: 'gingva' names no label (fix: give a kind (tooth, contact, marker, gingiva, "
        "background), an FDI number such as 13, 'tooth 13' or 'contact 13-14')"]


@pytest.mark.parametrize("side", ["golden", "candidate"])
def test_a_golden_or_candidate_without_labels_compares_pixels_as_before(tmp_path, moved_13, side):
    golden, candidate = write_pair(tmp_path, *moved_13, with_labels=(side != "golden", side != "candidate"))
    outcome = imgdiff(golden, candidate)
    (g, _), (c, _) = moved_13
    before = compare_images(g, c, GL, GL, Tolerance(), names=(str(golden), str(candidate)))
    assert outcome.explanation is None and outcome.exit_code == 1
    assert outcome.line == f"{before.summary()} -> {tmp_path / 'candidate.diff.png'}"
    assert outcome.lines == [outcome.line]


@pytest.mark.parametrize("damage", ["flipped byte", "no npz", "no json", "other pixels", "unknown id", "bad json"])
def test_a_damaged_or_mismatched_label_file_is_refused_in_one_line_exit_2(tmp_path, moved_13, damage):
    golden, candidate = write_pair(tmp_path, *moved_13)
    npz, meta = labels_paths(golden)
    if damage == "flipped byte":
        data = bytearray(npz.read_bytes())
        data[len(data) // 2] ^= 0xFF
        npz.write_bytes(bytes(data))
    elif damage == "no npz":
        npz.unlink()
    elif damage == "no json":
        meta.unlink()
    elif damage == "other pixels":
        (g, gl), (c, _) = moved_13
        write_labels(golden, gl, c)  # the labels of golden.png, but checksummed against other pixels
    elif damage == "unknown id":
        data = json.loads(meta.read_text())
        data["legend"] = [e for e in data["legend"] if e["teeth"] != [13]]
        meta.write_text(json.dumps(data))
    else:
        meta.write_text("{not json")
    r = orthosim("imgdiff", str(golden), str(candidate))
    assert r.returncode == 2, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "(fix: " in lines[0] and "Traceback" not in r.stderr
    assert str(npz) in lines[0] or str(meta) in lines[0]
    assert r.stdout == "" and not (tmp_path / "candidate.diff.png").exists()


def test_labels_round_trip_through_their_files(tmp_path, moved_13):
    (g, gl), _ = moved_13
    write_labels(tmp_path / "g.png", gl, g)
    back = read_labels(tmp_path / "g.png", g)
    assert np.array_equal(back.labels, gl.labels) and back.legend == gl.legend and back.camera == gl.camera
    assert np.array_equal(np.isnan(back.depth_mm), np.isnan(gl.depth_mm))
    assert np.allclose(back.depth_mm, gl.depth_mm, equal_nan=True)
    assert read_labels(tmp_path / "none.png", g) is None


def test_update_carries_the_candidates_labels_to_the_golden(tmp_path, moved_13):
    golden, candidate = write_pair(tmp_path, *moved_13, with_labels=(False, True))
    outcome = imgdiff(golden, candidate, update=True)
    assert outcome.exit_code == 0
    (_, _), (c, cl) = moved_13
    assert read_labels(golden, c).legend == cl.legend
    (tmp_path / "plain.png").write_bytes(encode_png(c))
    imgdiff(golden, tmp_path / "plain.png", update=True)  # a candidate without labels: the old ones go
    assert not any(p.exists() for p in labels_paths(golden))


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
@pytest.mark.real_data
def test_on_real_teeth_a_moved_canine_and_a_removed_incisor_are_named_exactly():
    """The patient's CBCT-segmented teeth (about 890,000 triangles, 31 teeth): the same claims as on
    the parametric ones."""
    import warnings

    from orthosim import load_case

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the scan's estimated axes and interpenetrations, said elsewhere
        real = load_case(ROOT / "cases" / "open_full_jaw_patient26.toml").build_dentition()
    rest = real.rest_poses()
    canine = real.teeth[13]
    move = -0.4 * (rest[13][:3, :3] @ canine.mesial)
    golden, golden_labels, scene = draw(real, FrameState(poses=rest), "right_buccal")
    candidate, candidate_labels, _ = draw(real, FrameState(poses=moved(real, 13, move)), "right_buccal")
    px, mm = expected_shift(scene, canine.to_world(canine.crown_center), move)
    found = explain(golden, golden_labels, candidate, candidate_labels)
    (change,) = found.changes
    assert change.subject == "tooth 13" and change.direction.startswith("distally")
    assert abs(change.shift_length_px - px) < 1.0 and abs(change.shift_mm - mm) < 0.05, (found.text(), px, mm)
    visible = sum(1 for e in golden_labels.legend if e.kind == "tooth")
    assert found.unchanged_teeth == visible - 1

    golden, golden_labels, _ = draw(real, FrameState(poses=rest), "frontal")
    candidate, candidate_labels, _ = draw(real, FrameState(poses=rest, extracted=frozenset({31})), "frontal")
    visible = sum(1 for e in golden_labels.legend if e.kind == "tooth")
    assert explain(golden, golden_labels, candidate, candidate_labels).text() == \
        f"tooth 31 disappeared; {visible - 1} other teeth unchanged"
