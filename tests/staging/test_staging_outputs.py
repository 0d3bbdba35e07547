"""What a lab and a clinician get from `orthosim stage`: stage models a lab prints (one closed body
per tooth, in mm, where the plan puts each tooth), a certificate whose clearances bracket the true
ones, `stage verify` that accepts a written staging and names the first violation of an edited one,
refuses a damaged folder in one line, and a staging page that loads offline with its charts."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import trimesh

from cli_helpers import orthosim, reaped
from orthosim.exchange.case import CASES_DIR, load_case
from orthosim.geometry import meshquery
from orthosim.geometry.motion import interpolate_pose
from orthosim.model import fdi as F
from orthosim.exchange.target import ToothMovement, target_pose

CROWDING = CASES_DIR / "staging_lower_incisor_crowding.toml"
DIASTEMA = CASES_DIR / "staging_midline_diastema.toml"
SHIPPED = sorted(CASES_DIR.glob("staging_*.toml"))

# its tests share one costly set-up: the module is scheduled first (tests/conftest.py)
pytestmark = pytest.mark.heavy_setup


@pytest.fixture(scope="module")
def crowding(tmp_path_factory):
    """The crowding case staged with stage models (STL) and pictures."""
    out = tmp_path_factory.mktemp("crowding") / "out"
    r = orthosim("stage", CROWDING, "--out", out, "--export", "stl", "--size", "320x240")
    assert r.returncode == 0, r.stderr
    return out


@pytest.fixture(scope="module")
def diastema(tmp_path_factory):
    out = tmp_path_factory.mktemp("diastema") / "out"
    r = orthosim("stage", DIASTEMA, "--out", out, "--no-render")
    assert r.returncode == 0, r.stderr
    return out


@pytest.fixture(scope="module")
def dent():
    return load_case(CROWDING).build_dentition()


def _stages(folder):
    return json.loads((folder / "stages.json").read_text())


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_stage_models_hold_one_closed_body_per_tooth_in_mm_where_the_plan_puts_it(crowding, dent):
    stages = _stages(crowding)
    last = stages["stages"]
    for k in (0, last):
        poses = {int(n): np.array(T) for n, T in stages["poses"][k]["poses"].items()}
        for arch, quadrants in (("lower", (3, 4)), ("upper", (1, 2))):
            teeth = sorted(n for n in poses if F.quadrant(n) in quadrants)
            mesh = trimesh.load(crowding / "models" / f"stage_{k:02d}_{arch}.stl")
            bodies = mesh.split(only_watertight=False)
            assert len(bodies) == len(teeth)
            assert all(b.is_watertight for b in bodies)
            # each body is one tooth where the plan puts it: same volume (mm^3) and centre (mm)
            expected = {n: dent.teeth[n].world_mesh(poses[n]) for n in teeth}
            for body in bodies:
                n = min(teeth, key=lambda m: np.linalg.norm(expected[m].center_mass - body.center_mass))
                assert np.linalg.norm(expected[n].center_mass - body.center_mass) < 1e-3
                assert body.volume == pytest.approx(expected[n].volume, rel=1e-4)
                np.testing.assert_allclose(body.extents, expected[n].extents, atol=1e-3)
                assert 3.0 < body.extents.max() < 40.0  # a tooth in millimetres, not metres


def test_the_certificate_lists_every_tooth_against_its_limit_and_the_ipr_pair_at_stage_one(crowding):
    cert = json.loads((crowding / "certificate.json").read_text())
    stages = _stages(crowding)
    assert cert["summary"]["within_limits"] and cert["summary"]["contact_free"]
    assert len(cert["transitions"]) == stages["stages"]
    limits = cert["limits"]
    for t in cert["transitions"]:
        assert sorted(x["fdi"] for x in t["teeth"]) == sorted(stages["teeth"])
        for x in t["teeth"]:
            assert all(abs(x[k]) <= v + 1e-7 for k, v in limits.items())
        assert all(c["min_clearance_mm"] > 0.0 for c in t["clearances"])
    first = cert["transitions"][0]
    assert [(r["fdi_a"], r["fdi_b"]) for r in first["ipr"]] == [(41, 42)]
    pair = [c for c in first["clearances"] if (c["fdi_a"], c["fdi_b"]) == (41, 42)]
    assert pair and pair[0]["ipr_mm"] > 0.5  # measured reduced, as planned
    assert all(not t["ipr"] for t in cert["transitions"][1:])


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_certified_clearances_bracket_densely_sampled_exact_distances(crowding, dent):
    """The reported least clearance is no lower than the truth by more than the tolerance, and
    never above what 401 FCL distances along the same motion find."""
    cert = json.loads((crowding / "certificate.json").read_text())
    stages = _stages(crowding)
    tol = cert["method"]["clearance_tolerance_mm"]
    checked = 0
    for t in cert["transitions"][1:8]:
        k = t["stage"]
        for c in t["clearances"]:
            if not c["relative_motion"] or c["ipr_mm"] > 0:
                continue
            a, b = c["fdi_a"], c["fdi_b"]
            P0, P1 = stages["poses"][k - 1]["poses"], stages["poses"][k]["poses"]
            ts = np.linspace(0.0, 1.0, 401)
            pa, pb = interpolate_pose(np.array(P0[str(a)]), np.array(P1[str(a)]), ts), \
                interpolate_pose(np.array(P0[str(b)]), np.array(P1[str(b)]), ts)
            oa, ob = meshquery.fcl_object(dent.teeth[a].mesh), meshquery.fcl_object(dent.teeth[b].mesh)
            dense = []
            for Ta, Tb in zip(pa, pb):
                meshquery.set_pose(oa, Ta)
                meshquery.set_pose(ob, Tb)
                dense.append(meshquery.distance(oa, ob))
            assert c["lower_bound_mm"] <= min(dense) + 1e-6
            assert c["min_clearance_mm"] - c["lower_bound_mm"] <= tol + 1e-6
            checked += 1
    assert checked >= 5


@pytest.mark.slow
@pytest.mark.parametrize("case", SHIPPED, ids=lambda p: p.stem)
def test_each_shipped_staging_case_exports_models_charts_and_a_certificate_that_verify_accepts(tmp_path, case, request):
    if case == CROWDING:  # the module's staging of it, made with the same exports (and pictures)
        out = request.getfixturevalue("crowding")
    else:
        out = tmp_path / "out"
        r = orthosim("stage", case, "--out", out, "--no-render", "--export", "stl")
        assert r.returncode == 0, r.stderr
    n = _stages(out)["stages"]
    assert len(list((out / "models").glob("stage_*_*.stl"))) == 2 * (n + 1)
    assert (out / "charts" / "staging_chart.png").stat().st_size > 10_000
    assert (out / "charts" / "ipr_chart.png").stat().st_size > 10_000
    cert = json.loads((out / "certificate.json").read_text())
    assert cert["summary"]["within_limits"] and cert["summary"]["contact_free"]
    v = orthosim("stage", "verify", out)
    assert v.returncode == 0, v.stdout + v.stderr
    assert f"all {n} stages of 28 teeth hold" in v.stdout


def _edited_copy(src, dst, edit):
    shutil.copytree(src, dst)
    data = _stages(dst)
    edit(data)
    (dst / "stages.json").write_text(json.dumps(data))
    return dst


def _moved(dent, data, stage, fdi, **movement):
    pose = np.array(data["poses"][stage]["poses"][str(fdi)])
    data["poses"][stage]["poses"][str(fdi)] = target_pose(dent.teeth[fdi], pose, ToothMovement(**movement)).tolist()


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_verify_accepts_the_written_staging_and_catches_an_added_collision_and_limit_overrun(diastema, dent, tmp_path):
    ok = orthosim("stage", "verify", diastema)
    assert ok.returncode == 0, ok.stdout + ok.stderr

    def edit(data):
        _moved(dent, data, 1, 17, mesial_mm=-0.3)  # molar pushed 0.3 mm distally in stage 1: over 0.25
        _moved(dent, data, 3, 11, mesial_mm=1.0)  # central pushed into the other central in stage 3

    bad = _edited_copy(diastema, tmp_path / "bad", edit)
    r = orthosim("stage", "verify", bad, "--all")
    assert r.returncode == 1, r.stdout + r.stderr
    lines = r.stdout.splitlines()
    assert "stage 1: limit: tooth 17 moves -0.3000 mm mesial, beyond the limit of 0.25 mm" in lines[0]
    assert any("stage 3: contact: teeth 11 and 21 intersect" in line for line in lines)
    # with limits wide enough, the collision alone is the first violation
    r = orthosim("stage", "verify", bad, "--limits", "mesial=5")
    assert r.returncode == 1 and "stage 3: contact: teeth 11 and 21 intersect" in r.stdout


def _translation(x, y=0.0, z=0.0):
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def _spheres_passing(offset_mm):
    """A unit sphere moving from x = -3 to x = +3 past one at rest at the origin, offset_mm apart sideways."""
    from orthosim.staging.sweep import ToothBodies

    ball = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    bodies = ToothBodies({1: ball, 2: ball.copy()})
    P0 = {1: _translation(-3.0, offset_mm), 2: np.eye(4)}
    P1 = {1: _translation(3.0, offset_mm), 2: np.eye(4)}
    return bodies.motion(1, 2, P0, P1)


def test_a_body_passing_through_another_between_two_stages_is_caught_though_both_ends_are_apart():
    from orthosim.staging.sweep import first_contact_on_grid

    motion = _spheres_passing(1.5)  # overlap 0.5 mm at mid-stage
    assert not motion.intersects(0.0) and not motion.intersects(1.0)
    t = first_contact_on_grid(_spheres_passing(1.5), step_mm=0.005)
    # the centres come within 2 mm at x = -sqrt(4 - 1.5^2): t = (3 - 1.3229) / 6
    assert t is not None and t == pytest.approx((3 - np.sqrt(4 - 1.5 ** 2)) / 6, abs=0.005)
    assert first_contact_on_grid(_spheres_passing(2.02), step_mm=0.005) is None  # passes 0.02 mm apart


def test_a_turning_bar_sweeps_into_a_ball_beside_it_mid_stage():
    from orthosim.staging.sweep import ToothBodies, first_contact_on_grid
    from orthosim.geometry.motion import rotation_matrix

    bar = trimesh.creation.box(extents=(10.0, 1.0, 1.0))
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    bodies = ToothBodies({1: bar, 2: ball})
    turned = np.eye(4)
    turned[:3, :3] = rotation_matrix(np.array([0.0, 0.0, np.pi / 2]))
    at_45 = _translation(3.0 / np.sqrt(2), 3.0 / np.sqrt(2))  # the ball on the bar's path at 45 degrees
    motion = bodies.motion(1, 2, {1: np.eye(4), 2: at_45}, {1: turned, 2: at_45})
    assert not motion.intersects(0.0) and not motion.intersects(1.0)
    t = first_contact_on_grid(motion, step_mm=0.005)
    # the bar's side (0.5 mm off its axis) meets the ball when 3 sin(45 deg - angle) = 1
    assert t is not None and t == pytest.approx((45 - np.degrees(np.arcsin(1 / 3))) / 90, abs=0.005)


def test_the_least_clearance_of_a_passing_body_is_its_analytic_value_within_the_tolerance():
    from orthosim.staging.sweep import min_clearance

    c = min_clearance(_spheres_passing(2.5), tolerance_mm=1e-3)
    # two unit spheres whose centres pass 2.5 mm apart: 0.5 mm at mid-stage (faceting: within 0.01 mm)
    assert c.min_mm == pytest.approx(0.5, abs=0.01) and abs(c.time - 0.5) < 0.01
    assert 0.0 <= c.min_mm - c.lower_bound_mm <= 1e-3


@pytest.mark.parametrize("damage, message", [
    (lambda p: p.write_text(p.read_text()[:500]), "stages.json: is unreadable"),
    (lambda p: p.write_text(p.read_text().replace('"stage": 2,', '"stage": 7,', 1)), "poses[2].stage: must be stage 2"),
    (lambda p: p.write_text(json.dumps({**json.loads(p.read_text()), "teeth": [11, 11]})), "teeth: names a tooth twice"),
    (lambda p: p.unlink(), "stages.json: is missing"),
])
def test_verify_refuses_a_damaged_folder_in_one_line(diastema, tmp_path, damage, message):
    bad = tmp_path / "bad"
    shutil.copytree(diastema, bad)
    damage(bad / "stages.json")
    r = orthosim("stage", "verify", bad)
    assert r.returncode == 2, r.stdout + r.stderr
    assert message in r.stderr and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_verify_refuses_a_staging_whose_case_changed(diastema, tmp_path):
    case = tmp_path / "case.toml"
    case.write_text(DIASTEMA.read_text().replace("mesial_mm = 1.0", "mesial_mm = 0.9", 1))
    r = orthosim("stage", "verify", diastema, "--case", case)
    assert r.returncode == 2 and "is not the case file this staging was written from" in r.stderr


def test_a_pose_that_is_not_a_rigid_motion_is_refused(diastema, tmp_path):
    def edit(data):
        data["poses"][1]["poses"]["11"][0][0] = 2.0

    bad = _edited_copy(diastema, tmp_path / "scaled", edit)
    r = orthosim("stage", "verify", bad)
    assert r.returncode == 2 and "poses[1].poses.11: is not a rigid motion" in r.stderr


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_the_staging_page_loads_offline_in_chromium_with_its_charts_and_pictures(crowding):
    from orthosim_render.report.browser import NAMES, load_page

    if not any(shutil.which(n) for n in NAMES):
        pytest.fail("headless Chromium is not installed: run `bash tools/dev.sh install`")
    html = (crowding / "index.html").read_text()
    assert 'src="data:image/png;base64,' in html and "http" not in html.replace("http-equiv", "")
    loaded = load_page(crowding / "index.html")
    assert loaded.problems == [] and loaded.network_requests == []
    assert loaded.images == 2 + 2 * 3  # two charts, first and last stage from three views
    assert b"IHDR" in loaded.screenshot_png[:32]
    for name in ("Staging chart", "IPR chart", "Movement table", "Certificate", "First and last stage"):
        assert f"<h2>{name}</h2>" in html


def _listing(folder):
    return sorted((str(p.relative_to(folder)), p.stat().st_size) for p in folder.rglob("*"))


def test_stage_into_a_folder_another_run_holds_is_refused_in_one_line(diastema, tmp_path):
    from orthosim.runtime.outputfolder import output_folder

    out = tmp_path / "held"
    shutil.copytree(diastema, out)
    before = _listing(out)
    with output_folder(out):  # this test holds the folder, as a staging in progress would
        r = orthosim("stage", DIASTEMA, "--out", out, "--no-render")
        assert _listing(out) == before  # the refused staging wrote nothing there
    assert r.returncode == 2 and "another orthosim run" in r.stderr and r.stderr.count("\n") == 1


@pytest.mark.skipif(not hasattr(__import__("os"), "killpg"), reason="POSIX signals")
def test_a_staging_stopped_mid_way_leaves_the_earlier_one_whole(diastema, tmp_path):
    import signal
    import subprocess
    import sys
    import time

    from cli_helpers import ROOT

    out = tmp_path / "o"
    shutil.copytree(diastema, out)
    before = _listing(out)
    proc = subprocess.Popen([sys.executable, "-c", "from orthosim.cli import entry; entry()", "stage", str(DIASTEMA),
                             "--out", str(out), "--no-render"], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    with reaped(proc):
        deadline = time.monotonic() + 120
        while not list(tmp_path.glob(".o.orthosim-staging-*")) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert list(tmp_path.glob(".o.orthosim-staging-*")), "the staging never started writing"
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 143, stderr
    assert _listing(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"]  # no private folder or lock left


def test_glb_and_ply_stage_models_hold_the_same_teeth_as_the_plan(diastema, dent, tmp_path):
    from orthosim.staging.models import export_stage_models

    stages = _stages(diastema)
    poses = [{int(n): np.array(T) for n, T in s["poses"].items()} for s in stages["poses"][:2]]
    for fmt in ("glb", "ply"):
        files = export_stage_models(dent, poses, tmp_path / fmt, fmt)
        assert sorted(p.name for p in files) == sorted(f"stage_{k:02d}_{a}.{fmt}" for k in (0, 1) for a in ("upper", "lower"))
    scene = trimesh.load(tmp_path / "glb" / "stage_01_upper.glb")
    assert sorted(scene.graph.nodes_geometry) == sorted(f"tooth_{n}" for n in poses[1] if F.quadrant(n) in (1, 2))
    T, _ = scene.graph["tooth_11"]
    np.testing.assert_allclose(T, poses[1][11], atol=1e-6)  # the pose at stage 1, mm
    ply = trimesh.load(tmp_path / "ply" / "stage_01_lower.ply")
    assert len(ply.split(only_watertight=True)) == 14


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_verify_refuses_an_inflated_reduction_that_would_hide_a_contact(crowding, tmp_path):
    def edit(data):
        data["ipr"][0]["ipr_mm"] = 2.0  # 41/42 overlap by about 0.58 mm at the target

    bad = _edited_copy(crowding, tmp_path / "ipr", edit)
    r = orthosim("stage", "verify", bad)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "stage 1: ipr: IPR of 41/42 (2.000 mm): more than the teeth overlap at the target (0.58" in r.stdout
