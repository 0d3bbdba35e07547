"""Aligner staging: limits hold in every stage, every stage's motion is free of contact (checked
here by dense sampling with exact FCL queries, independently of the planner), a conflict-free
set-up takes exactly the lower bound, teeth that must pass each other take more, and crowding
gets the interproximal reduction that the exact overlap asks for."""

from __future__ import annotations

import itertools
import subprocess
import sys

import numpy as np
import pytest

from orthosim.exchange.case import CASES_DIR, load_case
from orthosim.geometry import meshquery
from orthosim.geometry.motion import interpolate_pose
from orthosim.errors import CaseError, OrthosimError
from orthosim.model.parametric import parametric_dentition
from orthosim.staging.caseplan import plan_case
from orthosim.staging.limits import StageLimits
from orthosim.staging.plan import plan_staging
from orthosim.exchange.target import ToothMovement, movement_components, target_pose

DISTALISATION = CASES_DIR / "staging_molar_distalisation.toml"


@pytest.fixture(scope="module")
def dent():
    return parametric_dentition("smooth")


@pytest.fixture(scope="module")
def distalisation():
    return plan_case(DISTALISATION)


def _moved(dent, movements):
    start = dent.rest_poses()
    return start, {**start, **{n: target_pose(dent.teeth[n], start[n], m) for n, m in movements.items()}}


def _assert_within_limits(dent, plan):
    lim = plan.limits.array()
    for k in range(plan.n_stages):
        a, b = plan.poses(k), plan.poses(k + 1)
        for n in plan.teeth:  # measured again from the poses, not from the planner's own progress
            c = movement_components(dent.teeth[n], plan.start[n], a[n], b[n])
            assert np.all(np.abs(c) <= lim + 1e-7), (k + 1, n, c)
    for n in plan.teeth:
        np.testing.assert_allclose(plan.poses(plan.n_stages)[n], plan.target[n], atol=1e-9)


def _first_sampled_contact(dent, plan, samples=24, meshes=None):
    """(stage, a, b, t) of the first contact FCL finds at `samples` + 1 times of each stage's
    motion, among every pair with a moving tooth whose crowns are within 30 mm; None when none.
    meshes: FDI -> the tooth-frame mesh to use instead of the dentition's (reduced teeth)."""
    meshes = meshes or {}
    objs = {n: meshquery.fcl_object(meshes.get(n, dent.teeth[n].mesh)) for n in plan.teeth}
    centres = {n: dent.teeth[n].to_world(dent.teeth[n].crown_center, plan.start[n]) for n in plan.teeth}
    ts = np.linspace(0.0, 1.0, samples + 1)
    for k in range(plan.n_stages):
        a, b = plan.poses(k), plan.poses(k + 1)
        moving = {n for n in plan.teeth if not np.array_equal(a[n], b[n])}
        for x, y in itertools.combinations(plan.teeth, 2):
            if not ({x, y} & moving) or np.linalg.norm(centres[x] - centres[y]) > 30.0:
                continue
            px, py = interpolate_pose(a[x], b[x], ts), interpolate_pose(a[y], b[y], ts)
            for t, Tx, Ty in zip(ts, px, py):
                meshquery.set_pose(objs[x], Tx)
                meshquery.set_pose(objs[y], Ty)
                if meshquery.collide(objs[x], objs[y])[0]:
                    return k + 1, x, y, t
    return None


def test_a_setup_without_conflicts_takes_exactly_the_lower_bound(dent):
    start, target = _moved(dent, {17: ToothMovement(mesial_mm=-1.0), 16: ToothMovement(mesial_mm=-1.0),
                                  15: ToothMovement(mesial_mm=-0.6, buccal_mm=0.3)})
    plan = plan_staging(dent, start, target)
    assert plan.lower_bound == 4  # 1 mm at 0.25 mm per stage
    assert plan.n_stages == 4 and not plan.held and not plan.ipr
    _assert_within_limits(dent, plan)
    assert _first_sampled_contact(dent, plan) is None


def test_tighter_limits_give_more_stages_and_are_never_exceeded(dent):
    start, target = _moved(dent, {17: ToothMovement(mesial_mm=-1.0), 16: ToothMovement(mesial_mm=-1.0, rotation_deg=-3)})
    plan = plan_staging(dent, start, target, StageLimits.parse("mesial=0.1,rotation=0.5"))
    assert plan.lower_bound == 10
    assert plan.n_stages >= 10
    _assert_within_limits(dent, plan)


def test_a_premolar_that_must_wait_for_the_molars_takes_more_stages_than_the_bound(dent, distalisation):
    plan = distalisation.plan
    assert plan.lower_bound == 24  # 6 mm buccal at 0.25 mm per stage
    assert plan.n_stages > plan.lower_bound
    assert {n for _, n in plan.held} == {15}  # the premolar waits, the molars lead
    i15, i16 = plan.teeth.index(15), plan.teeth.index(16)
    assert plan.progress[-1, i15] == 1.0 and plan.progress[-1, i16] == 1.0
    _assert_within_limits(dent, plan)


def test_every_stage_of_the_distalisation_is_contact_free_by_dense_exact_sampling(dent, distalisation):
    assert _first_sampled_contact(dent, distalisation.plan) is None


def test_the_same_setup_moved_at_once_would_collide(dent, distalisation):
    """The sampling check can fail: staging every tooth together, without the planner's holds, hits."""
    plan = distalisation.plan
    import dataclasses

    together = dataclasses.replace(plan, progress=np.array([[min(1.0, k / plan.lower_bound)] * len(plan.teeth)
                                                            for k in range(plan.lower_bound + 1)]))
    hit = _first_sampled_contact(dent, together)
    assert hit is not None and {hit[1], hit[2]} == {15, 16}


def _overlap_along(dent, a, Ta, b, Tb, u, step=0.002):
    oa, ob = meshquery.fcl_object(dent.teeth[a].mesh), meshquery.fcl_object(dent.teeth[b].mesh)
    meshquery.set_pose(oa, Ta)
    d = 0.0
    while True:
        T = Tb.copy()
        T[:3, 3] += d * u
        meshquery.set_pose(ob, T)
        if not meshquery.collide(oa, ob)[0]:
            return d
        d += step


def test_crowding_gets_the_least_ipr_cut_that_frees_the_contact_and_stages_with_it(dent):
    from orthosim.staging.ipr import CLEARANCE_MM, RESOLUTION_MM
    from orthosim.staging.reduction import contact_cuts, cut_tooth, reduced_depth, reduced_meshes

    start, target = _moved(dent, {42: ToothMovement(mesial_mm=0.4), 43: ToothMovement(mesial_mm=0.4)})
    plan = plan_staging(dent, start, target)
    assert [(r.a, r.b) for r in plan.ipr] == [(41, 42)]
    r = plan.ipr[0]
    assert _overlap_along(dent, 41, target[41], 42, target[42], r.direction) > 0.2  # the test's own stepping
    # the two cuts leave the target teeth apart by about the clearance; cuts shallower by twice the
    # bisection's resolution leave them intersecting: the least reduction that frees the contact
    cuts = contact_cuts(41, 42, r.amount_mm, r.direction, target[41], target[42])
    less = contact_cuts(41, 42, r.amount_mm - CLEARANCE_MM - 2 * RESOLUTION_MM, r.direction, target[41], target[42])
    for (ca, cb), apart in ((cuts, True), (less, False)):
        oa = meshquery.fcl_object(cut_tooth(dent.teeth[41].mesh, [ca]), memo=False)
        ob = meshquery.fcl_object(cut_tooth(dent.teeth[42].mesh, [cb]), memo=False)
        meshquery.set_pose(oa, target[41])
        meshquery.set_pose(ob, target[42])
        assert bool(meshquery.collide(oa, ob)[0]) is not apart
        if apart:
            assert meshquery.distance(oa, ob) <= CLEARANCE_MM
    # each tooth is shorter toward the other by half the reduction, measured on the cut mesh
    for c in cuts:
        full = dent.teeth[c.fdi].mesh
        assert reduced_depth(full, cut_tooth(full, [c]), c.normal) == pytest.approx(r.amount_mm / 2, abs=1e-9)
    assert plan.n_stages == plan.lower_bound == 2
    _assert_within_limits(dent, plan)
    # on the reduced teeth every stage is free; on the whole teeth the last stage is not
    whole = {41: dent.teeth[41].mesh, 42: dent.teeth[42].mesh}
    assert _first_sampled_contact(dent, plan, meshes=reduced_meshes(whole, plan.ipr, plan.target)) is None
    assert _first_sampled_contact(dent, plan) is not None

    for n in plan.teeth:
        np.testing.assert_allclose(plan.poses(plan.n_stages)[n], plan.target[n], atol=1e-9)


def test_shipped_staging_cases_validate():
    for name in ("staging_lower_incisor_crowding", "staging_midline_diastema", "staging_molar_distalisation"):
        case = load_case(CASES_DIR / f"{name}.toml")
        assert case.staging is not None and case.staging.target is not None


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_target_meshes_register_to_the_start_and_bad_ones_are_refused(tmp_path, dent):
    moved = target_pose(dent.teeth[41], dent.teeth[41].rest_pose, ToothMovement(buccal_mm=0.5, rotation_deg=5))
    (tmp_path / "final").mkdir()
    dent.teeth[41].world_mesh(moved).export(tmp_path / "final" / "41.stl")
    case = tmp_path / "c.toml"
    case.write_text('[model]\nkind = "parametric"\n[target]\nfolder = "final"\n')
    spec = load_case(case).staging
    _, target = spec.poses(dent)
    np.testing.assert_allclose(target[41], moved, atol=1e-3)
    bent = dent.teeth[41].world_mesh(moved)
    bent.apply_scale(1.05)
    bent.export(tmp_path / "final" / "41.stl")
    with pytest.raises(CaseError, match=r"target.folder \(41.stl\).*RMS"):
        load_case(case).staging.poses(dent)


@pytest.mark.parametrize("text, message", [
    ("[target.41]\nbucal_mm = 1\n", "target.41.bucal_mm: unknown key"),
    ("[target.19]\nbuccal_mm = 1\n", "unknown tooth 19"),
    ("[target.41]\nbuccal_mm = 40\n", "target.41.buccal_mm: 40 is beyond 20 mm"),
    ("[target]\nfolder = \"nowhere\"\n", "target.folder: no such folder"),
    ("[target]\n", "target: is empty"),
    ("[start]\nfolder = \"x\"\n", "start.folder: unknown key"),
])
def test_bad_targets_are_one_line_errors(tmp_path, text, message):
    case = tmp_path / "c.toml"
    case.write_text('[model]\nkind = "parametric"\n' + text)
    with pytest.raises(CaseError) as err:
        load_case(case)
    assert message in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("text, message", [
    ("mesial=0", "mesial: must be a positive number"),
    ("twist=1", "twist: unknown limit"),
    ("tip=1,tip=2", "tip: given twice"),
    ("tip", "is not name=value"),
])
def test_bad_limits_are_one_line_errors(text, message):
    with pytest.raises(OrthosimError, match=message):
        StageLimits.parse(text)


def test_stage_command_refuses_a_case_without_target_in_one_line(tmp_path):
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-c", "from orthosim.cli import entry; entry()", "stage", str(CASES_DIR / "normal_occlusion.toml"),
                        "--out", str(out), "--no-render"], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "target: missing" in r.stderr
    assert not out.exists()


def test_the_bench_setup_moves_all_28_teeth_with_a_lower_bound_of_30(dent):
    from orthosim_bench.staging import big_setup
    from orthosim.staging.plan import stage_counts

    start, target = big_setup(dent)
    totals = np.stack([movement_components(dent.teeth[n], start[n], start[n], target[n]) for n in dent.fdis])
    counts = stage_counts(totals, StageLimits())
    assert len(dent.fdis) == 28 and np.all(counts > 0) and counts.max() == 30


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_stage_command_writes_the_chart_the_poses_and_the_summary(tmp_path):
    import csv
    import json

    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-c", "from orthosim.cli import entry; entry()", "stage",
                        str(CASES_DIR / "staging_midline_diastema.toml"), "--out", str(out), "--no-render"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "4 stages (lower bound 4), IPR total 0.00 mm" in r.stdout
    stages = json.loads((out / "stages.json").read_text())
    assert stages["stages"] == 4 and len(stages["poses"]) == 5 and len(stages["poses"][0]["poses"]) == 28
    rows = list(csv.DictReader((out / "staging.csv").open()))
    assert len(rows) == 4 * 28
    moved = [float(x["mesial_mm"]) for x in rows if x["fdi"] == "11"]
    assert moved == pytest.approx([0.25] * 4, abs=1e-4)  # 1 mm mesial in four equal stages
    assert (out / "ipr.csv").read_text().startswith("fdi_a,fdi_b,ipr_mm")
    assert json.loads((out / "run.json").read_text())["complete"] is True
    assert not list(out.glob(".*"))


def test_a_cut_removes_exactly_its_depth_and_an_open_tooth_is_refused_in_one_line():
    import trimesh

    from orthosim.staging.reduction import EnamelCut, cut_tooth, reduced_depth

    box = trimesh.creation.box((8.0, 10.0, 6.0))  # mm, a stand-in tooth
    cut = EnamelCut(11, (1.0, 0.0, 0.0), 0.3)
    reduced = cut_tooth(box, [cut])
    assert reduced.is_watertight and reduced_depth(box, reduced, cut.normal) == pytest.approx(0.3, abs=1e-12)
    assert reduced.volume == pytest.approx(box.volume * (8.0 - 0.3) / 8.0, rel=1e-12)
    assert cut_tooth(box, [cut]) is reduced  # remembered, not cut again
    with pytest.raises(OrthosimError, match="tooth 11: is not a closed manifold solid"):
        cut_tooth(trimesh.Trimesh(box.vertices, box.faces[:-2]), [cut])
