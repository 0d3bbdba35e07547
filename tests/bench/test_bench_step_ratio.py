"""The bench's simulation step against the continuous detector, measured interleaved (orthosim_bench.render)."""

import pytest

from collision_helpers import median_split_tree
from movement_helpers import coarse_case
from orthosim.collision import CollisionModel
from orthosim.movement import MovementModel
from orthosim.model.parametric import parametric_dentition
from orthosim_bench.render import _step_against_detector


def test_the_step_and_the_detector_are_timed_in_turn_and_compared(tmp_path):
    dent = parametric_dentition("coarse")
    cm = CollisionModel.from_dentition(dent, tree_builder=median_split_tree)
    load = 'teeth = [15]\nforce_cN = 150\ndirection = "mesial"\nmovement = "translation"'
    model = MovementModel.build(coarse_case(tmp_path, (14, 24, 34, 44), load), dent, cm)
    out = _step_against_detector(model, "continuous", n_states=6, warmup=2)
    assert out["simulation_step_us"] > 0 and out["continuous_step_us"] > 0
    assert out["ratio"] == pytest.approx(out["simulation_step_us"] / out["continuous_step_us"])
    assert out["target_ratio"] == 3.0
