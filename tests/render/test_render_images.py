"""Renders of the normal-occlusion model: what a clinician relies on seeing in each image.

Images are checked for content (teeth fill a sensible share of the frame over the background,
upper and lower teeth in the frontal view, crowns and roots told apart, moving teeth tinted,
extracted teeth gone) and a known contact is looked up where its centre projects.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from orthosim_render.cameras import VIEW_NAMES
from orthosim_render.frame_state import FrameState
from orthosim_render.renderer import Renderer
from orthosim_render.scene import BACKGROUND, DentitionScene

ROOT = Path(__file__).resolve().parents[2]
SIZE = (320, 240)
BG = np.round(np.array(BACKGROUND) * 255)


@pytest.fixture(scope="module")
def dentition():
    from orthosim import load_case

    return load_case(ROOT / "cases" / "normal_occlusion.toml").build_dentition()


@pytest.fixture(scope="module")
def renderer():
    with Renderer(SIZE) as r:
        yield r


def is_background(px) -> np.ndarray:
    return np.all(np.abs(np.asarray(px, float)[..., :3] - BG) <= 1, axis=-1)


def is_contact_colour(px) -> bool:
    r, g, b = (float(v) for v in px[:3])
    return r > 150 and g < 0.35 * r and b < 0.7 * r


def pixel_at(image, view, point):
    col, row = view.project(np.asarray(point)[None], SIZE)[0]
    return image[int(round(row)), int(round(col))], (int(round(row)), int(round(col)))


def labial_point(dentition, fdi, level: float, pose=None) -> np.ndarray:
    """Arch-frame point on the labial surface of `fdi` at local height `level` (mm above the CEJ)."""
    t = dentition.teeth[fdi]
    v = t.mesh.vertices
    band = v[np.abs(v[:, 1] - level) < 0.6]
    local = band[np.argmax(band[:, 2])]  # most labial vertex at that height
    return t.to_world(local, pose)


def render(renderer, dentition, view="frontal", state=None, **scene_opts):
    scene = DentitionScene(dentition, SIZE, **scene_opts)
    scene.update(state or FrameState.rest(dentition))
    renderer_ = renderer
    image = renderer_.render(scene, view)
    return image, scene.current_view


# A scene's buffers live in one GL context, so each test builds its own scene; it is cheap.


@pytest.mark.parametrize("view", VIEW_NAMES)
def test_each_preset_frames_the_teeth_on_the_background(renderer, dentition, view):
    image, _ = render(renderer, dentition, view)
    teeth = ~is_background(image)
    share = teeth.mean()
    assert 0.12 < share < 0.85, f"{view}: teeth cover {share:.0%} of the frame"
    # the frame is not cropped: the border rows and columns are (almost all) background
    border = np.concatenate([teeth[0], teeth[-1], teeth[:, 0], teeth[:, -1]])
    assert border.mean() < 0.02, f"{view}: teeth touch the image border"
    assert is_background(image[0, 0]) and is_background(image[-1, -1])


def test_frontal_view_shows_upper_teeth_above_lower_teeth(renderer, dentition):
    image, view = render(renderer, dentition, "frontal")
    rows = {}
    for fdi in (11, 21, 31, 41, 16, 46):
        px, (row, _) = pixel_at(image, view, labial_point(dentition, fdi, 1.5))
        assert not is_background(px), f"tooth {fdi} is not visible in the frontal view"
        rows[fdi] = row
    assert rows[11] < rows[41] and rows[21] < rows[31]  # image rows grow downward


def test_crowns_ivory_roots_paler_and_cooler(renderer, dentition):
    image, view = render(renderer, dentition, "frontal")
    crown, _ = pixel_at(image, view, labial_point(dentition, 11, 3.0))
    root, _ = pixel_at(image, view, labial_point(dentition, 11, -5.0))
    crown, root = crown.astype(int), root.astype(int)
    assert crown[0] > crown[2] + 15, f"crown pixel {crown} is not ivory"
    assert root[2] > root[0] + 5, f"root pixel {root} is not bluish"


def test_hide_roots_removes_the_roots(renderer, dentition):
    image, view = render(renderer, dentition, "frontal", hide_roots=True)
    root, _ = pixel_at(image, view, labial_point(dentition, 11, -6.0))
    crown, _ = pixel_at(image, view, labial_point(dentition, 11, 3.0))
    assert is_background(root)
    assert not is_background(crown)


def test_moving_teeth_are_tinted_and_extracted_teeth_gone(renderer, dentition):
    point = labial_point(dentition, 11, 3.0)
    plain, view = render(renderer, dentition, "frontal")
    moving, _ = render(renderer, dentition, "frontal", FrameState.rest(dentition, moving={11}))
    gone, _ = render(renderer, dentition, "frontal", FrameState.rest(dentition, extracted={11}))
    p_plain, rc = pixel_at(plain, view, point)
    p_moving = moving[rc].astype(int)
    assert p_moving[1] > p_moving[0] + 15, f"moving tooth pixel {p_moving} is not tinted"
    assert not np.array_equal(gone[rc], p_plain)
    # only the moving tooth changes colour
    far, rc_far = pixel_at(plain, view, labial_point(dentition, 26, 2.0))
    assert np.array_equal(moving[rc_far], far)


def test_known_contact_shows_in_the_contact_colour_where_it_projects(renderer, dentition):
    # a contact sphere on the labial face of the upper right central incisor
    c = labial_point(dentition, 11, 3.0)
    state = FrameState.rest(dentition, contact_centers=c[None], contact_radii=np.array([0.8]), contact_pairs=((11, 21),))
    with_contact, view = render(renderer, dentition, "frontal", state)
    without, _ = render(renderer, dentition, "frontal")
    px, rc = pixel_at(with_contact, view, c)
    assert is_contact_colour(px), f"pixel {px} at the projected contact is not the contact colour"
    assert not is_contact_colour(without[rc])
    # and nowhere far from it
    far = with_contact.copy()
    far[max(rc[0] - 12, 0):rc[0] + 13, max(rc[1] - 12, 0):rc[1] + 13] = 0
    assert not any(is_contact_colour(p) for p in far.reshape(-1, 3)[::7])


def test_contact_markers_follow_the_state_as_their_number_changes(renderer, dentition):
    """The marker buffer grows and shrinks: only the current step's markers are drawn."""
    scene = DentitionScene(dentition, SIZE)
    c = labial_point(dentition, 11, 3.0)
    far = labial_point(dentition, 23, 3.0)
    rng = np.random.default_rng(1)
    many = far + rng.normal(scale=0.5, size=(3000, 3))
    scene.update(FrameState.rest(dentition, contact_centers=np.vstack([c[None], many]),
                                 contact_radii=np.full(3001, 0.5)))
    first = renderer.render(scene, "frontal")
    scene.update(FrameState.rest(dentition, contact_centers=c[None], contact_radii=np.array([0.8])))
    second = renderer.render(scene, "frontal")
    view = scene.current_view
    _, rc_far = pixel_at(first, view, far)
    assert is_contact_colour(first[rc_far])
    assert not is_contact_colour(second[rc_far])
    assert is_contact_colour(pixel_at(second, view, c)[0])


def test_faces_inside_contact_spheres_are_coloured(dentition):
    scene = DentitionScene(dentition, SIZE, contact_faces=True)
    c = labial_point(dentition, 11, 3.0)
    scene.update(FrameState.rest(dentition, contact_centers=c[None], contact_radii=np.array([1.0]),
                                 contact_pairs=((11, 21),)))
    d = scene.teeth[11]
    local = np.asarray(d.primitive.positions, float)
    inside = np.linalg.norm(dentition.teeth[11].to_world(local) - c, axis=1) <= 1.0
    colours = np.asarray(d.primitive.color_0)[:, :3]
    red = np.all(np.isclose(colours, scene_contact_colour()), axis=1)
    assert inside.any() and np.array_equal(red, inside)
    assert not np.any(np.all(np.isclose(np.asarray(scene.teeth[21].primitive.color_0)[:, :3],
                                        scene_contact_colour()), axis=1))
    # contacts gone: colours restored
    scene.update(FrameState.rest(dentition))
    assert not np.any(np.all(np.isclose(np.asarray(d.primitive.color_0)[:, :3], scene_contact_colour()), axis=1))


def scene_contact_colour():
    from orthosim_render.scene import CONTACT_COLOR

    return np.array(CONTACT_COLOR, np.float32)


def test_same_state_renders_identically(renderer, dentition):
    c = labial_point(dentition, 11, 3.0)
    state = FrameState.rest(dentition, moving={13}, contact_centers=c[None], contact_radii=np.array([0.8]))
    a, _ = render(renderer, dentition, "right_buccal", state)
    b, _ = render(renderer, dentition, "right_buccal", state)
    with Renderer(SIZE) as other:
        c2, _ = render(other, dentition, "right_buccal", state)
    assert np.array_equal(a, b) and np.array_equal(a, c2)


def test_alpha_output_has_a_transparent_background(dentition):
    with Renderer(SIZE, alpha=True) as r:
        image, view = render(r, dentition, "frontal")
    assert image.shape == (SIZE[1], SIZE[0], 4)
    assert image[0, 0, 3] == 0
    px, _ = pixel_at(image, view, labial_point(dentition, 11, 3.0))
    assert px[3] == 255


def test_shader_programs_are_compiled_once_not_per_frame(renderer, dentition):
    """Guards the OSMesa shader-cache fix: without it every frame compiles (and leaks) programs."""
    scene = DentitionScene(dentition, SIZE)
    scene.update(FrameState.rest(dentition, contact_centers=np.zeros((1, 3)), contact_radii=np.ones(1)))
    renderer.render(scene, "frontal")
    cache = renderer._inner._program_cache._program_cache
    n = len(cache)
    for _ in range(5):
        renderer.render(scene, "frontal")
    assert len(cache) == n


def test_static_image_cache_changes_speed_not_pixels(dentition):
    """Teeth that do not move are drawn once and reused; frames must equal a full redraw."""
    from orthosim_bench.render import SyntheticMotion

    motion = SyntheticMotion(dentition, n_markers=200, period=8)
    with Renderer(SIZE) as cached, Renderer(SIZE, static_cache=False) as plain:
        a_scene, b_scene = DentitionScene(dentition, SIZE), DentitionScene(dentition, SIZE)
        for i in range(6):
            state = motion(i)
            a_scene.update(state)
            b_scene.update(state)
            for view in ("frontal", "left_buccal"):
                assert np.array_equal(cached.render(a_scene, view), plain.render(b_scene, view)), (i, view)
        assert cached._inner.cache_hits > 0
        # a static tooth that moves invalidates the cached image
        poses = dict(state.poses)
        poses[26] = poses[26].copy()
        poses[26][:3, 3] += [0.0, 0.0, 1.5]
        moved = FrameState(poses=poses, moving=state.moving)
        for _ in range(3):
            a_scene.update(moved)
            b_scene.update(moved)
            assert np.array_equal(cached.render(a_scene, "frontal"), plain.render(b_scene, "frontal"))


def test_a_contact_sphere_listed_several_times_is_drawn_once_with_the_same_pixels(renderer, dentition):
    """The simulation lists a leaf sphere once per overlapping leaf of the other tooth; the scene
    draws each sphere once, and the frame must equal the one drawing every listing."""
    from orthosim_bench.render import SyntheticMotion

    rng = np.random.default_rng(3)
    for i, view in enumerate(("frontal", "right_buccal", "maxillary")):
        state = SyntheticMotion(dentition, n_markers=150, seed=i)(5 * i)
        # each sphere listed one to four times, repeats interleaved with other spheres, big and overlapping
        idx = rng.permutation(np.repeat(np.arange(state.n_contacts), rng.integers(1, 5, state.n_contacts)))
        # and some spheres about the same centre as another but bigger: distinct, so drawn
        grown = np.arange(0, state.n_contacts, 10)
        centers = np.concatenate([state.contact_centers[idx], state.contact_centers[grown]])
        radii = np.concatenate([4.0 * state.contact_radii[idx], 6.0 * state.contact_radii[grown]])
        listed = FrameState(poses=state.poses, moving=state.moving, contact_centers=centers, contact_radii=radii)
        once = DentitionScene(dentition, SIZE)
        every = DentitionScene(dentition, SIZE, unique_markers=False)
        once.update(listed)
        every.update(listed)
        assert len(once.markers.positions) == state.n_contacts + len(grown) < len(every.markers.positions) == len(radii)
        assert np.array_equal(renderer.render(once, view), renderer.render(every, view)), view


def test_contact_faces_are_drawn_in_the_contact_colour(renderer, dentition):
    """The Figure 7 option: tooth surface inside a contact sphere coloured, no marker drawn."""
    c = labial_point(dentition, 11, 3.0)
    state = FrameState.rest(dentition, contact_centers=c[None], contact_radii=np.array([1.2]), contact_pairs=((11, 21),))
    painted, view = render(renderer, dentition, "frontal", state, contact_faces=True, show_markers=False)
    hidden, _ = render(renderer, dentition, "frontal", state, show_markers=False)
    px, rc = pixel_at(painted, view, c)
    assert is_contact_colour(px)
    assert not is_contact_colour(hidden[rc])


def test_occlusal_views_keep_only_the_contacts_of_the_shown_arch(renderer, dentition):
    """Seen from below, contacts between lower teeth would float over the upper arch."""
    upper = labial_point(dentition, 11, 3.0)  # an upper crown (above the occlusal plane)
    lower = labial_point(dentition, 41, 3.0)  # a lower crown (below it)
    assert upper[1] > 1.5 and lower[1] < -1.5
    state = FrameState.rest(dentition, contact_centers=np.stack([upper, lower]), contact_radii=np.array([0.8, 0.8]))
    scene = DentitionScene(dentition, SIZE)
    scene.update(state)
    shown = {}
    for view in ("frontal", "maxillary_occlusal", "mandibular_occlusal"):
        renderer.render(scene, view)
        shown[view] = np.asarray(scene.markers.positions)[:, 1]
    assert len(shown["frontal"]) == 2
    assert np.allclose(shown["maxillary_occlusal"], [upper[1]])
    assert np.allclose(shown["mandibular_occlusal"], [lower[1]])


def test_exact_contact_faces_are_the_touching_part_of_what_the_spheres_cover(dentition):
    from orthosim.collision.contact_area import TOUCH_TOLERANCE_MM
    from orthosim.spheretree import cached_sphere_tree

    # the central incisors of the model touch within 0.05 mm at rest: their overlapping leaf spheres
    spheres = []
    for a, b in ((11, 21), (21, 11)):
        ta, tb = (cached_sphere_tree(dentition.teeth[n].mesh) for n in (a, b))
        ca = dentition.teeth[a].to_world(ta.leaf_centers)
        cb = dentition.teeth[b].to_world(tb.leaf_centers)
        near = np.linalg.norm(ca[:, None] - cb[None], axis=2) <= ta.leaf_radii[:, None] + tb.leaf_radii[None]
        keep = near.any(axis=1)
        spheres.append((ca[keep], ta.leaf_radii[keep]))
    centers = np.concatenate([c for c, _ in spheres])
    radii = np.concatenate([r for _, r in spheres])
    state = FrameState.rest(dentition, contact_centers=centers, contact_radii=radii, contact_pairs=((11, 21),))
    painted = {}
    for exact in (False, True):
        scene = DentitionScene(dentition, SIZE, contact_faces=True, contact_faces_exact=exact)
        scene.update(state)
        colours = np.asarray(scene.teeth[11].primitive.color_0)[:, :3]
        painted[exact] = np.all(np.isclose(colours, scene_contact_colour()), axis=1)
    assert painted[True].any()
    assert not np.any(painted[True] & ~painted[False])  # exact faces lie inside the spheres
    assert painted[True].sum() < 0.5 * painted[False].sum()  # and are far fewer than the spheres hold
    # every painted vertex is near the other incisor (within the tolerance plus one triangle)
    d = scene.teeth[11]
    world = dentition.teeth[11].to_world(np.asarray(d.primitive.positions, float)[painted[True]])
    other = dentition.teeth[21]
    from scipy.spatial import cKDTree
    gap, _ = cKDTree(other.to_world(other.mesh.vertices)).query(world)
    edge = float(dentition.teeth[11].mesh.edges_unique_length.max())
    assert gap.max() <= TOUCH_TOLERANCE_MM + 2 * edge
