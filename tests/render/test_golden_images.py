"""orthosim's own golden images (tests/golden/): what a change to the drawing, the model or the cases does to a render.

Each test renders through the public API (`orthosim_render.regression`) and checks the image with the
`orthosim_image_regression` fixture, as a user's test would: exact on the machine and Mesa build
the goldens were made with, within tolerance elsewhere. Frames are named by simulation step (a
paper case's last step), never by animation frame, and carry no text overlay.

When a change is meant to alter pixels (a new sphere-tree builder, other colours, a case edit),
regenerate every golden and its sidecar with ONE command, then review `git diff tests/golden`:

    PYOPENGL_PLATFORM=osmesa .venv/bin/python -m pytest tests/render/test_golden_images.py --orthosim-regen-all

Goldens here: the normal occlusion in each of the five views; each paper case's last step with its
contacts; the sphere tree of a first molar level by level (the paper's Figure 2); the report's
inter-arch distance map of case 1 before treatment.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from orthosim_render.cameras import VIEW_NAMES
from orthosim_render.regression import render_case_frame

ROOT = Path(__file__).resolve().parents[2]
CASES = ROOT / "cases"
GOLDEN_DIR = Path(__file__).resolve().parents[1] / "golden"
SIZE = (320, 240)
# each paper case in the view that shows its treatment: the buccal segments close extraction spaces,
# the incisors close a midline diastema
PAPER_CASES = {
    "case1_first_premolar_extraction": "right_buccal",
    "case2_second_premolar_extraction": "right_buccal",
    "case3_incisor_space_closure": "frontal",
}


@pytest.fixture
def orthosim_golden_dir() -> Path:
    """Our goldens share one folder (the issue's tests/golden/), not pytest-regressions' per-module one."""
    return GOLDEN_DIR


@pytest.mark.parametrize("view", VIEW_NAMES)
def test_normal_occlusion_in_each_view_matches_its_golden(orthosim_image_regression, view):
    frame = render_case_frame(CASES / "normal_occlusion.toml", step=0, view=view, size=SIZE)
    orthosim_image_regression.check(frame, f"normal_occlusion_{view}")


@pytest.mark.parametrize("case", PAPER_CASES)
def test_paper_case_last_step_with_contacts_matches_its_golden(orthosim_image_regression, case):
    frame = render_case_frame(CASES / f"{case}.toml", step=-1, view=PAPER_CASES[case], size=SIZE)
    assert frame.sidecar.frame_index > 0 and frame.sidecar.case_file == f"{case}.toml"
    orthosim_image_regression.check(frame, f"{case}_last_step_{PAPER_CASES[case]}")


def test_sphere_tree_levels_of_a_first_molar_match_their_golden(orthosim_image_regression):
    """Figure 2: tooth 16, then its spheres at every level below the root, side by side."""
    from orthosim import load_case
    from orthosim.spheretree import cached_sphere_tree
    from orthosim_render.spheretree_view import render_sphere_tree

    tooth = load_case(CASES / "normal_occlusion.toml").build_dentition().teeth[16]
    tree = cached_sphere_tree(tooth.mesh)
    levels = list(range(1, tree.depth))
    image = render_sphere_tree(tooth, tree, levels, size=(SIZE[0] // (1 + len(levels)), SIZE[1]))
    orthosim_image_regression.check(image, "spheretree_levels_tooth16")


def test_distance_map_of_case1_before_treatment_matches_its_golden(orthosim_image_regression):
    """The report's inter-arch distance map (an occlusal map): every upper crown vertex coloured by
    its exact distance to the lower arch, case 1 at rest, seen from below (maxillary occlusal)."""
    from orthosim import load_case
    from orthosim.analysis.distancemap import DistanceMapModel
    from orthosim_render.frame_state import FrameState
    from orthosim_render.frame import cached_renderer
    from orthosim_render.report.pictures import distance_colors
    from orthosim_render.scene import DentitionScene, paint_crowns

    case = load_case(CASES / "case1_first_premolar_extraction.toml")
    dent = case.build_dentition()
    poses = dent.rest_poses()
    maps = DistanceMapModel(dent).inter_arch(poses, absent=case.extractions)
    scene = DentitionScene(dent, SIZE, hide_roots=True, show_markers=False)  # as the report draws it: CEJ cut
    paint_crowns(scene, {n: distance_colors(m.distance_mm) for n, m in maps.items()})
    scene.update(FrameState(poses=poses, extracted=frozenset(case.extractions)))
    image = cached_renderer(SIZE).render(scene, "maxillary_occlusal")
    orthosim_image_regression.check(image, "distance_map_case1_initial_maxillary_occlusal")
