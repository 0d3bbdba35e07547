"""Impact response: linear and angular momentum conserved, kinetic energy lost as restitution says."""

import numpy as np
import pytest

from orthosim.movement.impact import Body, impact


def _bodies(rng):
    def body(com, v, w):
        A = rng.normal(size=(3, 3))
        inertia = A @ A.T + 3 * np.eye(3)  # symmetric positive definite, g*mm^2
        return Body(float(rng.uniform(0.5, 2.0)), np.asarray(com, float), inertia, np.asarray(v, float), np.asarray(w, float))

    a = body([0.0, 0.0, 0.0], [0.03, 0.001, -0.002], rng.normal(scale=1e-3, size=3))
    b = body([8.0, 1.0, 0.5], [-0.01, 0.0, 0.0], rng.normal(scale=1e-3, size=3))
    return a, b


@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_impact_conserves_linear_and_angular_momentum(e):
    a, b = _bodies(np.random.default_rng(3))
    hit = impact(a, b, point=[4.0, 0.6, 0.2], normal=[1.0, 0.0, 0.0], restitution=e)
    assert hit.impulse > 0
    p0 = a.linear_momentum() + b.linear_momentum()
    p1 = sum(x.linear_momentum() for x in hit.after)
    assert np.allclose(p0, p1, rtol=0, atol=1e-12)
    about = np.array([2.0, -3.0, 5.0])
    L0 = a.angular_momentum(about) + b.angular_momentum(about)
    L1 = sum(x.angular_momentum(about) for x in hit.after)
    assert np.allclose(L0, L1, rtol=0, atol=1e-12)


def test_a_perfectly_elastic_impact_loses_no_energy_and_an_inelastic_one_does():
    a, b = _bodies(np.random.default_rng(5))
    elastic = impact(a, b, [4.0, 0.6, 0.2], [1.0, 0.0, 0.0], 1.0)
    assert abs(elastic.kinetic_energy_lost) < 1e-12 * sum(x.kinetic_energy() for x in elastic.before)
    losses = [impact(a, b, [4.0, 0.6, 0.2], [1.0, 0.0, 0.0], e).kinetic_energy_lost for e in (0.8, 0.5, 0.0)]
    assert 0 < losses[0] < losses[1] < losses[2]


def test_after_the_impact_the_contact_points_separate_at_e_times_the_approach_speed():
    a, b = _bodies(np.random.default_rng(7))
    p, n = np.array([4.0, 0.6, 0.2]), np.array([1.0, 0.0, 0.0])

    def approach(x, y):
        return float(((x.velocity + np.cross(x.omega, p - x.center_of_mass))
                      - (y.velocity + np.cross(y.omega, p - y.center_of_mass))) @ n)

    hit = impact(a, b, p, n, 0.4)
    assert approach(*hit.after) == pytest.approx(-0.4 * approach(a, b), rel=1e-9)


def test_teeth_moving_apart_do_not_collide():
    a, b = _bodies(np.random.default_rng(9))
    hit = impact(a, b, [4.0, 0.6, 0.2], [-1.0, 0.0, 0.0], 0.5)  # normal reversed: separating
    assert hit.impulse == 0.0 and hit.kinetic_energy_lost == 0.0
