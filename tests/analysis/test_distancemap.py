"""The inter-arch distance map is exact: sampled crown vertices agree with FCL within 0.01 mm, and a
vertex pushed into an opposing tooth is marked as penetrating."""

from __future__ import annotations

import fcl
import numpy as np
import pytest
import trimesh

from orthosim.geometry.meshquery import fcl_object, set_pose
from orthosim.analysis.distancemap import CONTACT, FAR, NEAR, PENETRATION, DistanceMapModel, classify, summarize
from orthosim.model.fdi import Arch, arch_of
from orthosim.model.parametric import parametric_dentition
from orthosim.geometry.pose import translation


@pytest.fixture(scope="module")
def dent():
    return parametric_dentition("coarse")


@pytest.fixture(scope="module")
def maps(dent):
    return DistanceMapModel(dent)


def fcl_point_distance(point, objects) -> float:
    """FCL's distance (mm) from a point (a sphere of radius 1e-9 mm) to the nearest of `objects`."""
    probe = fcl.CollisionObject(fcl.Sphere(1e-9), fcl.Transform(np.asarray(point, float)))
    return min(fcl.distance(probe, o, fcl.DistanceRequest(), fcl.DistanceResult()) for o in objects)


def placed_objects(dent, poses, teeth):
    objs = []
    for n in teeth:
        o = fcl_object(dent.teeth[n].mesh)
        set_pose(o, poses[n])
        objs.append(o)
    return objs


def test_sampled_crown_vertices_match_fcl_within_a_hundredth_of_a_millimetre(dent, maps):
    poses = dent.rest_poses()
    result = maps.inter_arch(poses)
    rng = np.random.default_rng(7)
    checked = 0
    for fdi in (16, 11, 23, 36, 41, 45):
        others = placed_objects(dent, poses, [n for n in dent.fdis if arch_of(n) != arch_of(fdi)])
        tooth = dent.teeth[fdi]
        world = tooth.to_world(tooth.crown_vertices, poses[fdi])
        d = result[fdi].distance_mm
        assert len(d) == len(world)
        near = np.flatnonzero(np.isfinite(d))
        picks = np.concatenate([rng.choice(near, 12, replace=False), [np.argmin(d)]])
        for i in picks:
            assert abs(d[i]) == pytest.approx(fcl_point_distance(world[i], others), abs=0.01)
            checked += 1
        beyond = np.flatnonzero(~np.isfinite(d))[:3]
        for i in beyond:  # reported far: FCL agrees it is beyond the resolved range
            assert fcl_point_distance(world[i], others) > 4.99
    assert checked == 6 * 13


def test_a_lower_molar_pushed_into_the_upper_arch_shows_penetration(dent, maps):
    poses = dent.rest_poses()
    poses[46] = translation([0.0, 0.8, 0.0]) @ poses[46]  # 0.8 mm toward the upper molar
    d = maps.inter_arch(poses)[46].distance_mm
    assert (classify(d) == PENETRATION).any()
    tooth = dent.teeth[46]
    world = tooth.to_world(tooth.crown_vertices, poses[46])
    uppers = [n for n in dent.fdis if arch_of(n) is Arch.UPPER]
    inside = np.zeros(len(world), bool)
    for n in uppers:
        inside |= trimesh.Trimesh(dent.teeth[n].world_mesh(poses[n]).vertices,
                                  dent.teeth[n].mesh.faces).contains(world)
    assert np.array_equal(d < 0, inside), "the sign must say inside exactly where a ray test does"
    deepest = int(np.argmin(d))
    assert -d[deepest] == pytest.approx(fcl_point_distance(world[deepest], placed_objects(dent, poses, uppers)), abs=0.01)


def test_classes_follow_the_colour_bar_bounds():
    d = np.array([-0.3, 0.0, 0.05, 0.1, 1.9, 2.0, 2.1, np.inf])
    assert classify(d).tolist() == [PENETRATION, CONTACT, CONTACT, NEAR, NEAR, NEAR, FAR, FAR]


def test_contacts_include_neighbours_in_the_same_arch(dent, maps):
    """Neighbours touch within 0.05 mm in the parametric model: their contact areas show."""
    poses = dent.rest_poses()
    contacts = maps.contacts(poses)
    assert (classify(contacts[11].distance_mm) == CONTACT).any()
    assert set(contacts[11].nearest[classify(contacts[11].distance_mm) == CONTACT]) & {12, 21}
    s = summarize(contacts)
    assert s["both"]["vertices"] == sum(len(dent.teeth[n].crown_vertices) for n in dent.fdis)
