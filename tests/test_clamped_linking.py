"""A clamped rod's ray-closed linking number is Lk0 + phi / 2 pi on buckled states too (issue 19,
the defect to fix first). Before the fix the far clamp's twist angle carried the holonomy with the
wrong sign: a buckled rod met its clamp turned by phi - 4 pi Wr instead of phi, its writhe had the
wrong hand, and Lk came out as phi / 2 pi + 2 Wr (at phi = 4 pi with 10 % end shortening:
Wr = -0.107, Lk = 1.786). Straight rods (Wr = 0) and the onset of buckling (symmetric in the sign
of phi) could not show it."""
import math
from dataclasses import replace

import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.model.material import Material
from jaxrod.model.topology import linking_number, writhe

N = 24  # the size test_solvers and test_sparse_stability compile for clamped rods
SHORTENING = 0.1


@pytest.fixture(scope="module")
def shortened():
    """A rod of length 1 clamped at both ends, the far clamp moved 0.1 towards the near one along
    the axis (end shortening made by hand), equilibria at phi = 2 pi and 4 pi from a bowed start."""
    mat = Material.from_ratio(B=1.0, nu=0.5, D=0.01)
    rod = jr.clamped_rod(N=N, length=1.0, material=mat)
    c = np.asarray(rod.x_clamped).copy()
    c[2:, 2] -= SHORTENING
    q0 = np.asarray(rod.q_init).copy()
    n_free = N - 4
    xi = q0[:3 * n_free].reshape(n_free, 3)
    xi[:, 2] *= 1.0 - SHORTENING
    xi[:, 0] += 0.05 * np.sin(np.pi * np.arange(1, n_free + 1) / (n_free + 1))  # bowed: Euler's first mode
    q0[:3 * n_free] = xi.ravel()
    rod = replace(rod, x_clamped=jnp.asarray(c), q_init=jnp.asarray(q0))
    states = {}
    for turns in (0, 1, 2):
        e = jr.solve_equilibrium(rod, 2 * math.pi * turns, q0,
                                jr.EquilibriumOptions(method="lbfgs" if turns == 0 else "auto"))
        states[turns], q0 = e, np.asarray(e.q)
    return rod, states


def _turned(v, axis, angle):
    """v turned by angle about the unit axis (right-hand rule)."""
    return v * math.cos(angle) + np.cross(axis, v) * math.sin(angle) + axis * np.dot(axis, v) * (1 - math.cos(angle))


def test_buckled_clamped_rod_has_lk_phi_over_two_pi_and_writhe_of_the_twists_hand(shortened):
    rod, states = shortened
    for turns in (1, 2):
        e = states[turns]
        assert e.solution.converged
        assert abs(e.Lk - (rod.Lk0 + turns)) <= 1e-10, (turns, e.Wr, e.Tw, e.Lk)
        # positive twist coils the rod right-handedly: the writhe takes the twist's sign (measured
        # +0.080 at one turn, +0.107 at two)
        assert e.Wr > 0.05
    # the far clamp holds the last edge's material director at the first one's, turned by phi
    axis = np.asarray(rod.axis)
    d_start = np.asarray(rod.director_start)
    for turns, e in states.items():
        d1 = np.asarray(rod.material_frames(jnp.asarray(e.q), e.phi)[0])
        assert np.max(np.abs(d1[0] - d_start)) <= 1e-12
        assert np.max(np.abs(d1[-1] - _turned(d_start, axis, e.phi))) <= 1e-10, turns


def test_the_ray_closed_ribbon_links_its_centreline_phi_over_two_pi_times(shortened):
    """Independent of the frames' bookkeeping: at whole turns the clamps' directors agree, so the
    centreline and a line on the rod surface, each extended along the axis and closed by the same
    far rectangle, are two closed polygons; their Gauss linking number is Lk. An integer: this
    catches a wrong 2 pi branch (a whole turn lost or gained), not a fraction of a turn, which the
    test above checks through the clamp's director."""
    rod, states = shortened
    axis, d_start = np.asarray(rod.axis), np.asarray(rod.director_start)
    far, wide = 50.0, 40.0
    side = np.cross(axis, d_start)  # the closing rectangle lies in the plane of the axis and `side`
    for turns, e in states.items():
        centre = np.asarray(e.x)
        stripe = np.asarray(rod.eccentric_line(jnp.asarray(e.q), e.phi, offset=0.002))

        def closed(line):  # the stripe's ends are offset by 0.002 d_start at both clamps: so is its closure
            a, b = line[0] - far * axis, line[-1] + far * axis
            return np.concatenate([[a], line, [b, b + wide * side, a + wide * side]])

        lk = float(linking_number(jnp.asarray(closed(centre)), jnp.asarray(closed(stripe))))
        assert abs(lk - turns) <= 1e-9, (turns, lk)


def test_exact_writhe_is_the_limit_of_ever_longer_rays(shortened):
    rod, states = shortened
    x = np.asarray(states[2].x)
    axis = np.asarray(rod.axis)
    wr = float(rod.exact_writhe(jnp.asarray(x)))
    ext = lambda far: np.concatenate([[x[0] - far * axis], x, [x[-1] + far * axis]])  # noqa: E731
    long_rays = [float(writhe(jnp.asarray(ext(far)), closed=False)) for far in (1e2, 1e3, 1e4)]
    errors = np.abs(np.array(long_rays) - wr)
    assert errors[-1] <= 1e-8 and errors[0] > errors[1] > errors[2]  # O(1 / ray length), towards wr


def test_past_greenhill_without_slack_lk_stays_phi_over_two_pi():
    """The issue's first case: clamps one rod length apart, twisted past Greenhill's threshold
    (4.29 pi here) to 6 pi and 6.5 pi, where the straight rod is unstable and the rod coils
    slightly (stretching: the ends cannot come closer). Measured Wr = +1.7e-4 and +2.3e-4."""
    mat = Material.from_ratio(B=1.0, nu=0.5, D=0.01)
    rod = jr.clamped_rod(N=N, length=1.0, material=mat)
    assert 6 * math.pi > jr.clamped_critical_twist(mat.B, mat.C)
    q0 = np.asarray(rod.q_init).copy()
    xi = q0[:3 * (N - 4)].reshape(N - 4, 3)
    s = np.arange(1, N - 3) / (N - 3)
    xi[:, 0] += 0.01 * np.sin(np.pi * s) ** 2 * np.cos(4 * np.pi * s)  # a right-handed coil to start from
    xi[:, 1] += 0.01 * np.sin(np.pi * s) ** 2 * np.sin(4 * np.pi * s)
    q0[:3 * (N - 4)] = xi.ravel()
    for turns in (3.0, 3.25):
        e = jr.solve_equilibrium(rod, 2 * math.pi * turns, q0=q0)
        q0 = np.asarray(e.q)
        assert e.solution.converged and e.stability.n_negative == 0
        assert np.max(np.abs(e.x[:, :2])) > 1e-3 and e.Wr > 1e-4  # buckled, right-handed
        assert abs(e.Lk - turns) <= 1e-10, (turns, e.Wr, e.Tw, e.Lk)
