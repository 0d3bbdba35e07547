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


def _ipr(stages):
    from orthosim.staging.ipr import InterproximalReduction

    return [InterproximalReduction(r["fdi_a"], r["fdi_b"], r["ipr_mm"], np.array(r["direction"])) for r in stages["ipr"]]


def _stage_meshes(dent, stages, k):
    """FDI -> the tooth-frame mesh stage k holds: whole at stage 0, reduced by the recorded IPR after."""
    from orthosim.staging.reduction import reduced_meshes

    whole = {n: dent.teeth[n].mesh for n in stages["teeth"]}
    last = {int(n): np.array(T) for n, T in stages["poses"][-1]["poses"].items()}
    return whole if k == 0 else reduced_meshes(whole, _ipr(stages), last)


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
            # each body is one tooth where the plan puts it: same volume (mm^3) and centre (mm),
            # reduced by the planned IPR from stage 1 on
            held = _stage_meshes(dent, stages, k)
            expected = {n: held[n].copy().apply_transform(poses[n]) for n in teeth}
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
            held = _stage_meshes(dent, stages, k)
            oa, ob = meshquery.fcl_object(held[a]), meshquery.fcl_object(held[b])
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
    # with limits wide enough, the collision is the one violation of the teeth; the certificate,
    # written for the stages before the edit, disagrees with them from stage 1 on
    r = orthosim("stage", "verify", bad, "--limits", "mesial=5", "--all")
    lines = r.stdout.splitlines()
    contacts = [line for line in lines if ": contact: " in line]
    assert r.returncode == 1 and not [line for line in lines if ": limit: " in line]
    assert "stage 3: contact: teeth 11 and 21 intersect" in contacts[0] and all("teeth 11 and 21" in c for c in contacts)
    assert "stage 1: certificate: certificate.json: transitions[1].teeth[17].mesial_mm claims " in r.stdout


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
        data["ipr"][0]["ipr_mm"] = 2.0  # 41/42 need about 1.2 mm

    bad = _edited_copy(crowding, tmp_path / "ipr", edit)
    r = orthosim("stage", "verify", bad)
    assert r.returncode == 1, r.stdout + r.stderr
    needed = _stages(crowding)["ipr"][0]["ipr_mm"]
    assert (f"stage 1: ipr: IPR of 41/42 (2.0000 mm): stages.json records 2.0000 mm, the case needs {needed:.4f} mm"
            in r.stdout), r.stdout


def _bodies_by_tooth(path, dent, poses, teeth):
    """FDI -> the closed body of an exported arch (STL, mm) that is that tooth (nearest centre)."""
    bodies = trimesh.load(path).split(only_watertight=False)
    assert len(bodies) == len(teeth)
    centres = {n: dent.teeth[n].to_world(dent.teeth[n].crown_center, poses[n]) for n in teeth}
    out = {}
    for body in bodies:
        n = min(teeth, key=lambda m: np.linalg.norm(body.bounds.mean(axis=0) - centres[m]))
        assert n not in out
        out[n] = body
    return out


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_the_exported_crowding_models_hold_no_intersection_and_each_ipr_contact_reduced_by_the_planned_amount(crowding, dent):
    """What the lab prints: FCL on the exported STL teeth finds no two intersecting at any stage,
    and from stage 1 on each IPR tooth reaches half the planned reduction less far toward its
    neighbour than the whole tooth does (measured on the exported mesh, in the tooth's frame)."""
    from orthosim.staging.reduction import contact_cuts

    stages = _stages(crowding)
    (ipr,) = stages["ipr"]
    a, b, amount = ipr["fdi_a"], ipr["fdi_b"], ipr["ipr_mm"]
    last = {int(n): np.array(T) for n, T in stages["poses"][-1]["poses"].items()}
    cuts = contact_cuts(a, b, amount, np.array(ipr["direction"]), last[a], last[b])
    cert = json.loads((crowding / "certificate.json").read_text())
    touching = {(c["fdi_a"], c["fdi_b"]) for c in cert["start"]["clearances"] if c["min_clearance_mm"] < 1e-6}
    assert (a, b) not in touching
    reductions = []
    for k in range(stages["stages"] + 1):
        poses = {int(n): np.array(T) for n, T in stages["poses"][k]["poses"].items()}
        teeth = {n: body for arch in ("upper", "lower")
                 for n, body in _bodies_by_tooth(crowding / "models" / f"stage_{k:02d}_{arch}.stl", dent, poses,
                                                 sorted(n for n in poses if (F.quadrant(n) in (1, 2)) == (arch == "upper"))).items()}
        objects = {n: meshquery.fcl_object(body, memo=False) for n, body in teeth.items()}
        for x, y in ((x, y) for x in teeth for y in teeth if x < y):
            if np.all(teeth[x].bounds[0] <= teeth[y].bounds[1]) and np.all(teeth[y].bounds[0] <= teeth[x].bounds[1]):
                if not meshquery.collide(objects[x], objects[y])[0]:
                    continue
                # neighbours the model itself has touching (certified clearance ~1e-10 mm at rest) meet
                # within the float32 rounding of STL (1e-5 mm at 100 mm); no other pair meets at all
                assert (x, y) in touching, f"stage {k}: teeth {x} and {y} intersect"
                depth = meshquery.penetration_depth(teeth[x], np.eye(4), teeth[y], np.eye(4))
                assert depth <= 1e-4, f"stage {k}: teeth {x} and {y} intersect {depth:.2g} mm deep"
        for c in cuts:  # how much less far the exported tooth reaches along its cut's normal
            local = trimesh.transform_points(teeth[c.fdi].vertices, np.linalg.inv(poses[c.fdi]))
            whole = np.asarray(dent.teeth[c.fdi].mesh.vertices) @ np.array(c.normal)
            reductions.append((k, c.fdi, float(whole.max() - (local @ np.array(c.normal)).max())))
    for k, n, depth in reductions:
        assert depth == pytest.approx(0.0 if k == 0 else amount / 2, abs=1e-4), (k, n, depth)
    assert amount > 0.5  # 41 comes into line from lingual: its contact with 42 is stripped on both sides


def _edited_certificate(src, dst, edit):
    shutil.copytree(src, dst)
    data = json.loads((dst / "certificate.json").read_text())
    edit(data)
    (dst / "certificate.json").write_text(json.dumps(data))
    return dst


def _every_clearance(cert):
    yield from cert["start"]["clearances"]
    for t in cert["transitions"]:
        yield from t["clearances"]


def _wider_clearances(cert):
    for c in _every_clearance(cert):
        c["min_clearance_mm"] += 0.5


CERTIFICATE_EDITS = [
    ("clearances 0.5 mm wider", _wider_clearances, "stage 0: certificate: certificate.json: start.clearances[11-12].min_clearance_mm claims "),
    ("largest limit use", lambda c: c["summary"]["largest_limit_use"].update(ratio=0.5),
     "certificate: certificate.json: summary.largest_limit_use.ratio claims 0.5, recomputed "),
    ("IPR amount", lambda c: c["transitions"][0]["ipr"][0].update(ipr_mm=0.3),
     "stage 1: certificate: certificate.json: transitions[1].ipr[41-42].ipr_mm claims 0.3, recomputed "),
]


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
@pytest.mark.parametrize("edit, first", [e[1:] for e in CERTIFICATE_EDITS], ids=[e[0] for e in CERTIFICATE_EDITS])
def test_verify_names_the_first_figure_an_edited_certificate_claims_wrongly(crowding, tmp_path, edit, first):
    bad = _edited_certificate(crowding, tmp_path / "bad", edit)
    r = orthosim("stage", "verify", bad)
    assert r.returncode == 1, r.stdout + r.stderr
    assert r.stdout.count("\n") == 1 and first in r.stdout, r.stdout


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_verify_refuses_a_certificate_missing_a_figure_in_one_line(crowding, tmp_path):
    bad = _edited_certificate(crowding, tmp_path / "bad", lambda c: c["summary"].pop("least_clearance"))
    r = orthosim("stage", "verify", bad)
    assert r.returncode == 2, r.stdout + r.stderr
    assert r.stderr.count("\n") == 1 and "certificate.json: summary.least_clearance: is missing" in r.stderr


@pytest.fixture(scope="module")
def certified(crowding):
    """(certificate.json's path and content, its recomputation from the written stages: what verify compares)."""
    from orthosim.staging.certificate import certificate_record, certify_stages
    from orthosim.staging.verify import load_for_verify
    from orthosim.storage.atomic import to_jsonable

    w, dent_, start, target = load_for_verify(crowding)
    cert = certify_stages(dent_, w.teeth, start, w.poses, w.limits, w.ipr, target)
    recomputed = json.loads(json.dumps(certificate_record(cert, w.case_file, w.case_sha256), default=to_jsonable))
    path = crowding / "certificate.json"
    return path, json.loads(path.read_text()), recomputed


def _beyond(rng, tolerance):
    """A change of a figure well outside its tolerance, either way."""
    return float(rng.choice([-1.0, 1.0]) * tolerance * rng.uniform(2.0, 500.0))


def _pick(rng, items):
    return items[int(rng.integers(len(items)))]


def _edit_clearance(cert, rng):
    where = [("start", c) for c in cert["start"]["clearances"]]
    where += [(f"transitions[{t['stage']}]", c) for t in cert["transitions"] for c in t["clearances"]]
    part, c = _pick(rng, where)
    field, tol = _pick(rng, [("min_clearance_mm", 1e-3), ("lower_bound_mm", 1e-3), ("at_time", 1e-5)])
    c[field] += _beyond(rng, tol)
    return f"{part}.clearances[{c['fdi_a']}-{c['fdi_b']}].{field}", c[field]


def _edit_limit_use(cert, rng):
    t = _pick(rng, cert["transitions"])
    tooth = _pick(rng, t["teeth"])
    field = _pick(rng, [k for k in tooth if k.endswith(("_mm", "_deg"))] + ["largest_ratio"])
    tooth[field] += _beyond(rng, 1e-6)
    return f"transitions[{t['stage']}].teeth[{tooth['fdi']}].{field}", tooth[field]


def _edit_ipr(cert, rng):
    where = [(f"transitions[{t['stage']}].ipr", r) for t in cert["transitions"] for r in t["ipr"]]
    where += [(f"transitions[{t['stage']}].clearances", c) for t in cert["transitions"] for c in t["clearances"] if c["ipr_mm"] > 0]
    part, r = _pick(rng, where)
    r["ipr_mm"] += _beyond(rng, 1e-4)
    return f"{part}[{r['fdi_a']}-{r['fdi_b']}].ipr_mm", r["ipr_mm"]


def _edit_summary(cert, rng):
    path = _pick(rng, ["largest_limit_use.ratio", "largest_limit_use.stage", "largest_limit_use.fdi", "least_clearance.min_clearance_mm",
                       "least_clearance.stage", "least_clearance.fdi_b", "ipr_total_mm", "pairs_within_reach", "transitions",
                       "within_limits", "contact_free"])
    *parents, name = path.split(".")
    node = cert["summary"]
    for p in parents:
        node = node[p]
    value = node[name]
    if isinstance(value, bool):
        node[name] = not value
    elif isinstance(value, int):
        node[name] = value + int(rng.choice([-3, -2, -1, 1, 2, 3]))
    else:
        node[name] = value + _beyond(rng, 1e-4 if name.startswith("ipr") else 1e-3)
    return f"summary.{path}", node[name]


def _edit_flag(cert, rng):
    t = _pick(rng, cert["transitions"])
    where = [(f"transitions[{t['stage']}]", t, "within_limits"), (f"transitions[{t['stage']}]", t, "contact_free")]
    where += [(f"transitions[{t['stage']}].teeth[{x['fdi']}]", x, "within") for x in t["teeth"]]
    where += [(f"transitions[{t['stage']}].clearances[{c['fdi_a']}-{c['fdi_b']}]", c, "relative_motion") for c in t["clearances"]]
    part, node, field = _pick(rng, where)
    node[field] = not node[field]
    return f"{part}.{field}", node[field]


def _edit_checksum(cert, rng):
    sha = cert["case_sha256"]
    i = int(rng.integers(len(sha)))
    cert["case_sha256"] = sha[:i] + _pick(rng, [h for h in "0123456789abcdef" if h != sha[i]]) + sha[i + 1:]
    return "case_sha256", cert["case_sha256"]


EDIT_KINDS = {"clearance": _edit_clearance, "limit use": _edit_limit_use, "IPR amount": _edit_ipr,
              "summary": _edit_summary, "flag": _edit_flag, "case checksum": _edit_checksum}


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_every_kind_of_certified_figure_edited_at_random_is_named_by_verify(certified, edit_tally):
    """Seeded random edits, one figure each, of every kind certificate.json certifies: the comparison
    `stage verify` makes names that figure with the value the file claims; the file as written passes."""
    import copy

    from orthosim.staging.certcheck import compare

    path, claimed, recomputed = certified
    assert compare(path, claimed, recomputed)[0] == []
    rng = np.random.default_rng(38)
    for i in range(120):
        kind = list(EDIT_KINDS)[i % len(EDIT_KINDS)]
        edited = copy.deepcopy(claimed)
        figure, value = EDIT_KINDS[kind](edited, rng)
        found, _ = compare(path, edited, recomputed)
        assert any(d.figure == figure and d.claimed == value for d in found), (kind, figure, value, found[:3])
        edit_tally[kind] = edit_tally.get(kind, 0) + 1


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_a_stage_model_edited_or_missing_is_named_against_stages_json(crowding, tmp_path):
    from orthosim.staging.modelcheck import check_stage_models
    from orthosim.staging.verify import load_for_verify

    bad = tmp_path / "bad"
    shutil.copytree(crowding, bad)
    model = bad / "models" / "stage_03_lower.stl"
    moved = trimesh.load(model)
    moved.apply_translation((0.0, 0.0, 0.05))  # the whole arch 0.05 mm labially: a stale or edited file
    model.write_bytes(moved.export(file_type="stl"))
    (bad / "models" / "stage_05_upper.stl").unlink()
    written, dent_, _, target = load_for_verify(bad)
    problems, checked = check_stage_models(bad / "models", written, dent_, target)
    assert checked == 2 * (written.n_stages + 1) - 1
    assert [(k, text.split(":")[0]) for k, text in problems] == [(3, "models/stage_03_lower.stl"), (5, "models/stage_05_upper.stl")]
    assert "not stage 3 as stages.json poses it" in problems[0][1] and "missing" in problems[1][1]
    assert check_stage_models(crowding / "models", written, dent_, target) == ([], 2 * (written.n_stages + 1))
