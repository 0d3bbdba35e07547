"""Force passed on through contacts: the paper's "part of its force passes to the tooth it hit, and so on"."""

import numpy as np
import pytest

from orthosim.movement.propagation import propagate

X = np.array([1.0, 0.0, 0.0])


def always(_tooth, _force):
    return True


def test_a_chain_of_three_touching_teeth_pushed_from_one_end_passes_the_shares_down_the_chain():
    # A -> B -> C touching in a row along +x; 200 cN on A toward B; share 0.5
    bal = propagate({1: 200 * X}, [(1, 2, X), (2, 3, X)], share=0.5, can_pass=always)
    assert np.allclose(bal.received[2], 100 * X)
    assert np.allclose(bal.received[3], 50 * X)
    # A and B push into their neighbours: blocked along the chain; C, free on its far side, moves
    assert np.allclose(bal.free[1], 0) and np.allclose(bal.free[2], 0)
    assert np.allclose(bal.free[3], 50 * X)
    assert set(bal.blocked_by) == {1, 2}


@pytest.mark.parametrize("share", [0.0, 0.3, 0.8])
def test_the_share_is_a_parameter(share):
    bal = propagate({1: 100 * X}, [(1, 2, X), (2, 3, X)], share=share, can_pass=always)
    assert np.allclose(bal.received[3], 100 * share**2 * X)


def test_only_the_pushing_component_is_passed_on_and_the_pushing_tooth_stops():
    f = np.array([60.0, 0.0, 80.0])  # 60 cN into the neighbour, 80 cN sideways
    bal = propagate({1: f}, [(1, 2, X)], share=0.5, can_pass=always)
    assert np.allclose(bal.received[2], 30 * X)
    assert np.allclose(bal.free[1], 0.0)  # the paper: on a collision the moving tooth stops


def test_a_tooth_pulled_away_from_its_neighbour_passes_nothing():
    bal = propagate({2: 100 * X}, [(1, 2, X)], share=0.5, can_pass=always)  # 2 pulled away from 1
    assert not bal.passed
    assert np.allclose(bal.free[2], 100 * X)


def test_opposite_pushes_meeting_in_a_chain_block_every_tooth():
    # 1 -> 2 -> 3 <- 4 (like both sides of an arch pushing toward the incisors)
    contacts = [(1, 2, X), (2, 3, X), (3, 4, X)]
    bal = propagate({1: 100 * X, 4: -100 * X}, contacts, share=0.5, can_pass=always)
    for t in (1, 2, 3, 4):
        assert np.linalg.norm(bal.free[t]) < 1e-6


def test_propagation_stops_where_the_force_no_longer_moves_a_tooth():
    moves = lambda tooth, force: force >= 40.0  # threshold 40 cN
    bal = propagate({1: 100 * X}, [(1, 2, X), (2, 3, X), (3, 4, X)], share=0.5, can_pass=moves)
    assert np.allclose(bal.received[2], 50 * X)
    assert np.allclose(bal.received[3], 25 * X)  # 2 had 50 cN: enough, it passed on
    assert np.allclose(bal.received[4], 0)  # 3 had 25 cN: below threshold, nothing passed


# --- in the running simulator -------------------------------------------------------------------

@pytest.mark.parametrize("share", [0.5, 0.7])
def test_a_molar_pushing_two_touching_teeth_moves_the_free_end_at_the_rate_of_its_share(tmp_path, share):
    """Upper right 17-16-15 touch; 14 is out, so 15 has room. 400 cN on 17 toward 16: 16 receives
    share x 400, 15 receives share x that, and 15 moves at the rate of what it receives into the
    space, toward the canine; 16 and 17, blocked, follow it."""
    from collision_helpers import median_split_tree
    from orthosim import load_case
    from orthosim.collision import CollisionModel
    from orthosim.movement import MovementModel, simulate
    from orthosim.mechanics.biomechanics import RateLaw
    from orthosim.model.parametric import parametric_dentition

    p = tmp_path / "chain.toml"
    p.write_text(f"""
[model]
kind = "parametric"
resolution = "coarse"
[treatment]
extractions = [14]
duration_days = 28
step_days = 7
[simulation]
force_share = {share}
[[loads]]
teeth = [17]
force_cN = 400
direction = "mesial"
movement = "translation"
""")
    case = load_case(p)
    dent = parametric_dentition("coarse")
    model = MovementModel.build(case, dent, CollisionModel.from_dentition(dent, tree_builder=median_split_tree))
    recs = list(simulate(model, "continuous"))
    c = {n: dent.teeth[n].to_world(dent.teeth[n].crown_center) for n in (17, 16, 15, 13)}

    def toward(a, b):  # the paper's director vector, in the occlusal plane
        v = (c[b] - c[a]) * [1, 0, 1]
        return v / np.linalg.norm(v)

    f = recs[1].forces
    # each pushed tooth receives the share of the push, along the arch toward its own next tooth
    assert np.allclose(f.received[16], share * 400 * toward(16, 15), atol=1e-6)
    assert np.allclose(f.received[15], share * share * 400 * toward(15, 13), atol=1e-6)
    assert set(f.blocked_by) >= {16, 17} and 15 not in f.blocked_by
    rate = RateLaw().rate(np.linalg.norm(f.received[15]), model.mechanics[15].root_area_mm2)
    step1 = recs[1].poses[15][:3, 3] - recs[0].poses[15][:3, 3]
    assert np.linalg.norm(step1) == pytest.approx(rate * 7, rel=1e-6)
    moved = {n: np.linalg.norm(recs[-1].poses[n][:3, 3] - recs[0].poses[n][:3, 3]) for n in (15, 16, 17, 13)}
    assert moved[13] == 0.0
    assert moved[16] > 0.5 * moved[15] and moved[17] > 0.5 * moved[15]  # the chain closes up behind it


def test_the_stacked_push_of_every_edge_is_each_edges_own_dot_product_to_the_last_bit():
    # propagate finds total[i] @ n_ij of all edges in one stacked product: it must be numpy's very
    # dot product of each pair (a sum written out, or einsum, differs in the last bit)
    rng = np.random.default_rng(11)
    total = rng.normal(size=(5000, 3)) * rng.uniform(0, 300, (5000, 1))
    n = rng.normal(size=(5000, 3))
    stacked = (total[:, None, :] @ n[:, :, None]).reshape(-1)
    assert np.array_equal(stacked, np.array([t @ m for t, m in zip(total, n)]))
