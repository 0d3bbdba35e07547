"""Image regression as a CI user meets it: `orthosim imgdiff` and the comparison behind it.

A render that did not change passes; a tooth moved by 0.2 mm and one missing contact marker are
caught; a golden from another Mesa build is compared within tolerance (and 1-level noise passes);
unusable input (a truncated golden, a missing file, not a PNG, another size) exits 2 with one line.
Renders are 320x240 and reuse the goldens in tests/golden/.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from orthosim_render.imgdiff import (DIFF_COLOUR, GoldenSidecar, Tolerance, compare_images, diff_image, read_png,
                            read_sidecar, sidecar_path, write_golden)
from orthosim_render.png import encode_png
from cli_helpers import orthosim

ROOT = Path(__file__).resolve().parents[2]
CASES = ROOT / "cases"
GOLDEN = ROOT / "tests" / "golden"
NORMAL_FRONTAL = GOLDEN / "normal_occlusion_frontal.png"
CASE3_FRONTAL = GOLDEN / "case3_incisor_space_closure_last_step_frontal.png"


def other_mesa(sidecar: GoldenSidecar) -> GoldenSidecar:
    return dataclasses.replace(sidecar, mesa_version="99.0.0-elsewhere")


def copy_golden(src: Path, dst: Path, sidecar: GoldenSidecar | None = None) -> Path:
    shutil.copyfile(src, dst)
    data = (sidecar or read_sidecar(src)).to_json()
    sidecar_path(dst).write_text(json.dumps(data))
    return dst


# ------------------------------------------------------------------------- renders against goldens


def test_an_unchanged_render_passes_its_golden_exactly(tmp_path):
    from orthosim_render.regression import render_case_frame

    frame = render_case_frame(CASES / "normal_occlusion.toml", step=0, view="frontal")
    candidate = tmp_path / "frontal.png"
    candidate.write_bytes(encode_png(frame.image))  # no sidecar: imgdiff asks this machine's GL
    r = orthosim("imgdiff", str(NORMAL_FRONTAL), str(candidate))
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("match (exact: same ")
    assert "0 of 76800 pixels differ" in r.stdout
    assert not (tmp_path / "frontal.diff.png").exists()  # nothing to show


def test_a_tooth_moved_by_0_2_mm_is_caught_exactly_and_within_tolerance():
    from orthosim_render.frame import render_state
    from orthosim_render.regression import DEFAULT_SIZE, simulate_case_once

    run = simulate_case_once(CASES / "normal_occlusion.toml", steps=0)
    state = run.state(0)
    tooth = run.dentition.teeth[11]
    pose = state.poses[11].copy()
    pose[:3, 3] += 0.2 * (pose[:3, :3] @ tooth.mesial)  # 0.2 mm toward the midline
    moved = render_state(run.dentition, dataclasses.replace(state, poses={**state.poses, 11: pose}), "frontal",
                         DEFAULT_SIZE)
    golden, sidecar = read_png(NORMAL_FRONTAL), read_sidecar(NORMAL_FRONTAL)

    exact = compare_images(golden, moved, sidecar, sidecar)
    assert exact.mode == "exact" and not exact.matched
    tolerant = compare_images(golden, moved, sidecar, other_mesa(sidecar))
    assert tolerant.mode == "tolerance" and not tolerant.matched
    assert tolerant.beyond_pixels > 2 * Tolerance().max_fraction * golden.shape[0] * golden.shape[1]


def test_one_missing_contact_marker_is_caught(tmp_path):
    """Case 3's last step drawn with one contact sphere left out: the one nearest the frontal camera."""
    from orthosim_render.frame import render_state
    from orthosim_render.regression import DEFAULT_SIZE, simulate_case_once

    run = simulate_case_once(CASES / "case3_incisor_space_closure.toml")
    state = run.state(-1)
    spheres = np.column_stack([state.contact_centers, state.contact_radii]).astype(np.float32)
    distinct = np.unique(spheres, axis=0)
    nearest = distinct[np.argmax(distinct[:, 2])]  # the frontal camera looks along -z
    keep = ~np.all(spheres == nearest, axis=1)
    one_less = dataclasses.replace(state, contact_centers=state.contact_centers[keep],
                                   contact_radii=state.contact_radii[keep])
    assert len(np.unique(spheres[keep], axis=0)) == len(distinct) - 1
    image = render_state(run.dentition, one_less, "frontal", DEFAULT_SIZE)
    golden, sidecar = read_png(CASE3_FRONTAL), read_sidecar(CASE3_FRONTAL)

    result = compare_images(golden, image, sidecar, sidecar)
    assert result.mode == "exact" and not result.matched and result.differing_pixels > 0
    # and the diff image marks the gap where the marker was drawn
    diff = diff_image(golden, image, result)
    col, row = run_view_projection(run, "frontal", nearest[:3])
    marks = np.all(diff[:, 2 * golden.shape[1]:] == DIFF_COLOUR, axis=2)
    near = marks[max(row - 6, 0):row + 7, max(col - 6, 0):col + 7]
    assert near.any(), "the diff image shows no difference where the missing marker was"


def run_view_projection(run, view: str, point) -> tuple[int, int]:
    from orthosim_render.scene import DentitionScene

    scene = DentitionScene(run.dentition, (320, 240))
    col, row = scene.view(view).project(np.asarray(point, float)[None], (320, 240))[0]
    return int(round(col)), int(round(row))


# ---------------------------------------------------------------------------------- modes


def test_a_sidecar_naming_another_mesa_switches_to_tolerance_and_1_level_noise_passes(tmp_path):
    golden = read_png(NORMAL_FRONTAL)
    noise = np.random.default_rng(7).integers(-1, 2, golden.shape)
    noisy = np.clip(golden.astype(int) + noise, 0, 255).astype(np.uint8)
    assert np.count_nonzero(noisy != golden) > 0.5 * golden.size
    candidate = tmp_path / "noisy.png"
    candidate.write_bytes(encode_png(noisy))
    sidecar_path(candidate).write_text(json.dumps(read_sidecar(NORMAL_FRONTAL).to_json()))  # drawn here

    elsewhere = copy_golden(NORMAL_FRONTAL, tmp_path / "elsewhere.png", other_mesa(read_sidecar(NORMAL_FRONTAL)))
    r = orthosim("imgdiff", str(elsewhere), str(candidate))
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("match (tolerance: Mesa 99.0.0-elsewhere vs ")
    assert "SSIM 0.9" in r.stdout and len(r.stdout.strip().splitlines()) == 1

    # the same noise against a golden from this very Mesa build is a difference: exact mode
    here = copy_golden(NORMAL_FRONTAL, tmp_path / "here.png")
    r = orthosim("imgdiff", str(here), str(candidate), "--diff", str(tmp_path / "out" / "d.png"))
    assert r.returncode == 1
    line = r.stdout.strip()
    assert line.startswith("differ (exact: same ") and "largest difference 1 level," in line
    assert line.endswith(f"-> {tmp_path / 'out' / 'd.png'}") and (tmp_path / "out" / "d.png").is_file()


def test_tolerance_counts_pixels_beyond_max_level_against_max_fraction():
    golden = np.full((100, 100, 3), 100, np.uint8)
    candidate = golden.copy()
    candidate[0, :10] = 104  # 10 pixels off by 4 levels: 0.1 % of 10,000
    tol = compare_images(golden, candidate, None, None)
    assert tol.mode == "tolerance" and tol.beyond_pixels == 10 and tol.matched
    candidate[1, 0] = 104  # one more pixel: beyond 0.1 %
    assert not compare_images(golden, candidate, None, None).matched
    assert compare_images(golden, candidate, None, None, Tolerance(max_level=4)).matched


def test_the_diff_image_is_golden_candidate_and_differences_over_grey():
    golden = np.zeros((20, 30, 3), np.uint8)
    golden[5:15, 5:25] = (200, 180, 150)
    candidate = golden.copy()
    candidate[8, 12] = (0, 0, 0)
    result = compare_images(golden, candidate, None, None)
    diff = diff_image(golden, candidate, result)
    assert diff.shape == (20, 90, 3)
    assert np.array_equal(diff[:, :30], golden) and np.array_equal(diff[:, 30:60], candidate)
    panel = diff[:, 60:]
    assert tuple(panel[8, 12]) == DIFF_COLOUR
    grey = panel[10, 20]
    assert grey[0] == grey[1] == grey[2]  # the rest is a grey copy of the golden


# ------------------------------------------------------------------------------ bad input


def test_a_truncated_golden_gives_exit_2_and_a_clear_message(tmp_path):
    golden = tmp_path / "golden.png"
    golden.write_bytes(NORMAL_FRONTAL.read_bytes()[:4000])
    r = orthosim("imgdiff", str(golden), str(NORMAL_FRONTAL))
    assert r.returncode == 2
    assert r.stderr.strip() == f"orthosim: error: {golden}: golden is truncated (fix: restore the golden (git checkout, or regenerate it))"
    assert r.stdout == "" and "Traceback" not in r.stderr


@pytest.mark.parametrize("problem", ["missing", "not a png", "empty", "other size", "bad sidecar"])
def test_unusable_input_exits_2_with_one_line_naming_the_file(tmp_path, problem):
    golden = copy_golden(NORMAL_FRONTAL, tmp_path / "golden.png")
    candidate = copy_golden(NORMAL_FRONTAL, tmp_path / "candidate.png")  # with a sidecar: no GL probe needed
    named = candidate
    if problem == "missing":
        candidate.unlink()
    elif problem == "not a png":
        candidate.write_bytes(b"\xff\xd8\xff\xe0 a JPEG header")
    elif problem == "empty":
        candidate.write_bytes(b"")
    elif problem == "other size":
        candidate.write_bytes(encode_png(np.zeros((480, 640, 3), np.uint8)))
    else:
        sidecar_path(golden).write_text('{"mesa_version": 22}')
        named = sidecar_path(golden)
    r = orthosim("imgdiff", str(golden), str(candidate))
    assert r.returncode == 2, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"orthosim: error: {named}") and "(fix: " in lines[0]
    assert "Traceback" not in r.stderr and not list(tmp_path.glob("*.diff.png"))


# --------------------------------------------------------------------------------- update


def test_update_rewrites_the_golden_and_its_sidecar_and_says_so(tmp_path):
    golden = copy_golden(NORMAL_FRONTAL, tmp_path / "golden.png", other_mesa(read_sidecar(NORMAL_FRONTAL)))
    candidate = tmp_path / "candidate.png"
    shutil.copyfile(CASE3_FRONTAL, candidate)
    shutil.copyfile(sidecar_path(CASE3_FRONTAL), sidecar_path(candidate))
    r = orthosim("imgdiff", str(golden), str(candidate), "--update")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"updated golden {golden} and {sidecar_path(golden)} from {candidate} (it was: differ")
    assert np.array_equal(read_png(golden), read_png(CASE3_FRONTAL))
    assert read_sidecar(golden) == read_sidecar(CASE3_FRONTAL)
    r = orthosim("imgdiff", str(golden), str(candidate))
    assert r.returncode == 0 and r.stdout.startswith("match (exact")


def test_a_golden_made_from_another_version_of_its_case_says_so():
    golden, sidecar = read_png(NORMAL_FRONTAL), read_sidecar(NORMAL_FRONTAL)
    edited = dataclasses.replace(sidecar, case_sha256="0" * 64)
    result = compare_images(golden, golden, sidecar, edited)
    assert result.matched and "made from another version of normal_occlusion.toml" in result.summary()


def test_help_lists_imgdiff():
    r = orthosim("--help")
    line = next(l for l in r.stdout.splitlines() if l.strip().startswith("imgdiff "))
    assert "golden" in line


def test_write_golden_round_trips_pixels_and_sidecar(tmp_path):
    image = np.random.default_rng(1).integers(0, 256, (12, 16, 3)).astype(np.uint8)
    write_golden(tmp_path / "g.png", image, GoldenSidecar(gl_renderer="r", mesa_version="1.2.3", view="frontal"))
    assert np.array_equal(read_png(tmp_path / "g.png"), image)
    assert read_sidecar(tmp_path / "g.png").size == (16, 12)
    assert not list(tmp_path.glob(".*"))  # written atomically: no temporary left
