"""The Figure 2 mode: a tooth and its sphere tree level by level."""

import numpy as np
import pytest

from orthosim import OrthosimError
from orthosim.spheretree.tree import SphereTree
from orthosim_render.spheretree_view import SPHERE_COLOR, render_sphere_tree
from orthosim_render.standin import standin_dentition


def two_level_tree(tooth) -> SphereTree:
    v = tooth.mesh.vertices
    top, bottom = v[v[:, 1] >= 0], v[v[:, 1] < 0]
    cs = [p.mean(axis=0) for p in (top, bottom)]
    rs = [np.linalg.norm(p - c, axis=1).max() for p, c in zip((top, bottom), cs)]
    c0 = v.mean(axis=0)
    return SphereTree(branching=2, centers=(c0[None], np.array(cs)),
                      radii=(np.array([np.linalg.norm(v - c0, axis=1).max()]), np.array(rs)),
                      parents=(np.array([-1]), np.array([0, 0])),
                      leaf_of_face=np.where(tooth.mesh.triangles_center[:, 1] >= 0, 0, 1))


def sphere_coloured(panel) -> np.ndarray:
    rgb = panel.astype(int)
    return (rgb[..., 2] > rgb[..., 0] + 40) & (rgb[..., 2] > 120)  # the strong blue of SPHERE_COLOR


def test_panels_show_the_tooth_then_each_level():
    assert SPHERE_COLOR[2] > SPHERE_COLOR[0]
    tooth = standin_dentition().teeth[16]
    image = render_sphere_tree(tooth, two_level_tree(tooth), levels=[0, 1], size=(120, 160))
    assert image.shape == (160, 360, 3)
    tooth_panel, root_panel, leaf_panel = image[:, :120], image[:, 120:240], image[:, 240:]
    assert sphere_coloured(tooth_panel).mean() < 0.01
    # the root sphere covers more of its panel than the two tighter leaf spheres
    assert sphere_coloured(root_panel).mean() > sphere_coloured(leaf_panel).mean() > 0.05


def test_asking_for_a_missing_level_is_a_user_error():
    tooth = standin_dentition().teeth[11]
    with pytest.raises(OrthosimError, match="level"):
        render_sphere_tree(tooth, two_level_tree(tooth), levels=[5], size=(64, 64))
