"""Exact contact faces frame by frame: answers kept between frames colour the faces asked afresh."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from orthosim.collision.contact_area import TOUCH_TOLERANCE_MM, ContactSurface, faces_in_spheres, triangle_distances
from orthosim.exchange.case import load_case
from orthosim.spheretree.inside import Solid
from orthosim.runtime.strategies import step_records

from orthosim_render.contact_faces import ExactContactFaces
from orthosim_render.timeline import frames_from_steps

CASES = Path(__file__).resolve().parents[2] / "cases"
_SOLIDS: dict[int, Solid] = {}


def _touching_afresh(surface: ContactSurface, pose, candidates, other: ContactSurface, other_pose) -> set[int]:
    """The definition, asked afresh: candidates within the tolerance of any triangle of `other` near
    them (numpy's exact triangle distances, no pair left out early) or with the centroid inside it."""
    to_other = np.linalg.inv(other_pose) @ pose
    tri = surface.vertices[surface.faces[candidates]] @ to_other[:3, :3].T + to_other[:3, 3]
    centre = tri.mean(axis=1)
    reach = surface.circumradius[candidates] + other.circumradius.max() + TOUCH_TOLERANCE_MM
    lists = other.kdtree.query_ball_point(centre, reach)
    mine = np.repeat(np.arange(len(candidates)), [len(x) for x in lists])
    theirs = np.asarray([j for x in lists for j in x], np.int64)
    near = triangle_distances(tri[mine], other.triangles[theirs]) <= TOUCH_TOLERANCE_MM
    found = {int(c) for c in candidates[np.unique(mine[near])]}
    if id(other) not in _SOLIDS:
        _SOLIDS[id(other)] = Solid(other.vertices, other.faces)  # the voxel-grid inside test, not the surface's own
    inside = _SOLIDS[id(other)].contains(centre)
    return found | {int(c) for c in candidates[inside]}


@pytest.mark.slow  # simulates two steps and asks every frame's faces twice
def test_faces_kept_between_frames_are_those_asked_afresh_on_every_frame_of_a_simulated_case():
    case = load_case(CASES / "case1_first_premolar_extraction.toml")
    with step_records(case, "continuous", steps=2, in_process=True) as source:
        records, dentition = list(source.records), source.dentition
    frames = list(frames_from_steps(records, frozenset(case.extractions), per_step=2))
    kept = ExactContactFaces(dentition)
    asked = painted = 0
    for state in frames:
        for a, b in state.contact_pairs:
            if a in state.extracted or b in state.extracted:
                continue
            for fdi, partner in ((a, b), (b, a)):
                pose, other_pose = (np.asarray(state.poses[n], float) for n in (fdi, partner))
                faces = kept.faces(fdi, pose, [(partner, other_pose)], state.contact_centers, state.contact_radii)
                candidates = faces_in_spheres(kept.surface(fdi), pose, state.contact_centers, state.contact_radii)
                afresh = _touching_afresh(kept.surface(fdi), pose, candidates, kept.surface(partner), other_pose)
                assert set(faces.tolist()) == afresh, f"frame of step {state.step}, tooth {fdi} against {partner}"
                asked += 1
                painted += len(faces)
    assert asked > 10 and painted > 0
    assert kept.reused > 0 and kept.computed > 0  # teeth at rest within a step keep their answers
