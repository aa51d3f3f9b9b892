"""Tests for jaxrod.model.topology: writhe, linking number and their quadratures."""
import numpy as np
import pytest

import jax
import jax.numpy as jnp

import jaxrod  # noqa: F401  (enables float64)
from jaxrod.model import topology
from jaxrod.model.topology import (
    eccentric_line,
    gauss_linking_quadrature,
    linking_number,
    writhe,
    writhe_quadrature,
)


# ----------------------------------------------------------------- curves
def _param(n):
    """n equally spaced parameters on [0, 2 pi) for closed curves."""
    return 2.0 * np.pi * np.arange(n) / n


def trefoil(n):
    s = _param(n)
    return np.stack(
        [np.sin(s) + 2 * np.sin(2 * s), np.cos(s) - 2 * np.cos(2 * s), -np.sin(3 * s)], axis=1
    )


def wobbly_planar(n):
    """Non-convex, non-self-intersecting closed curve in the xy plane."""
    s = _param(n)
    r = 1.0 + 0.3 * np.cos(3 * s) + 0.1 * np.sin(2 * s)
    return np.stack([r * np.cos(s), r * np.sin(s), 0.0 * s], axis=1)


def ribbon(n, k, eps=0.1):
    """Unit circle (counter-clockwise in xy) and its ribbon edge x + eps*d1.

    Frame: t = tangent, u = outward radial, v = t x u, so (t, u, v) is right
    handed and d1 = cos(psi) u + sin(psi) v with psi = k s turns the director
    k times right-handedly about t: twist k, writhe 0, hence Lk = k.
    """
    s = _param(n)
    x = np.stack([np.cos(s), np.sin(s), 0.0 * s], axis=1)
    t = np.stack([-np.sin(s), np.cos(s), 0.0 * s], axis=1)
    u = x.copy()
    v = np.cross(t, u)
    psi = k * s
    d1 = np.cos(psi)[:, None] * u + np.sin(psi)[:, None] * v
    return x, np.asarray(eccentric_line(x, d1, eps))


def rotation(seed):
    """A random proper rotation matrix (det +1)."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def random_closed(n, seed):
    """Random non-planar closed polygon (a noisy, tilted, knotted-ish loop)."""
    rng = np.random.default_rng(seed)
    return trefoil(n) + 0.2 * rng.normal(size=(n, 3))


# ----------------------------------------------------------------- writhe
@pytest.mark.parametrize("curve", ["circle", "wobbly", "tilted"])
def test_writhe_planar_is_zero(curve):
    if curve == "circle":
        x = ribbon(40, 0)[0]
    elif curve == "wobbly":
        x = wobbly_planar(57)
    else:
        # Planar but in a generic plane: coplanarity is then only up to
        # rounding, which must not leak into the result.
        x = wobbly_planar(57) @ rotation(3).T + np.array([0.3, -1.0, 2.0])
    assert abs(float(writhe(x))) < 1e-12
    assert abs(float(writhe(x, closed=False))) < 1e-12


def test_writhe_invariances():
    x = trefoil(90)
    w = float(writhe(x))
    assert abs(float(writhe(x @ rotation(0).T)) - w) < 1e-12
    assert abs(float(writhe(x + np.array([5.0, -3.0, 7.0]))) - w) < 1e-12
    assert abs(float(writhe(3.7 * x)) - w) < 1e-12
    assert abs(float(writhe(0.01 * x)) - w) < 1e-12
    # Mirror image flips the sign.
    assert abs(float(writhe(x * np.array([1.0, 1.0, -1.0]))) + w) < 1e-12
    # Reversing the orientation leaves the writhe unchanged.
    assert abs(float(writhe(x[::-1])) - w) < 1e-12
    # Cyclic relabelling of the vertices of a closed curve changes nothing.
    assert abs(float(writhe(np.roll(x, 17, axis=0))) - w) < 1e-12


def test_right_handed_helix_positive_writhe():
    t = np.linspace(0.0, 6.0 * np.pi, 200)
    helix = np.stack([np.cos(t), np.sin(t), 0.3 * t], axis=1)
    w = float(writhe(helix, closed=False))
    assert w > 0.0
    # Its mirror image (left-handed helix) has the opposite writhe.
    assert abs(float(writhe(helix * np.array([1.0, -1.0, 1.0]), closed=False)) + w) < 1e-12


def test_trefoil_writhe_converges():
    w200 = float(writhe(trefoil(200)))
    w400 = float(writhe(trefoil(400)))
    wq800 = float(writhe_quadrature(trefoil(800)))
    # Exact polygon writhe converges at second order in 1/N: |w200 - w400|
    # ~ 2e-5, far inside 1e-3.  The midpoint quadrature carries an O(h^2)
    # error as well (~2e-4 at N = 800).
    assert abs(w200 - w400) < 1e-3
    assert abs(w200 - wq800) < 1e-3
    assert abs(w400 - wq800) < 1e-3
    # This parametrisation is a left-handed trefoil: Wr ~ -3.3541.
    assert -3.36 < w400 < -3.35


def test_writhe_matches_literal_kl_formula():
    # The smooth solid-angle expression used internally equals the literal
    # Klenin-Langowski asin formula with its sign((r34 x r12).r13) factor.
    rng = np.random.default_rng(5)
    p = [rng.normal(size=(4000, 3)) for _ in range(4)]
    a = np.asarray(topology.solid_angle(*p))
    b = np.asarray(topology.solid_angle_literal(*p))
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


@pytest.mark.parametrize("closed", [True, False])
def test_writhe_equals_sum_over_all_ordered_pairs(closed):
    # ``writhe`` evaluates each unordered pair once, by cyclic offset; it must equal the
    # literal sum of Omega over every ordered non-adjacent pair (odd and even N, open and
    # closed, including the open rod's end pair (0, n-1) that no offset below n/2 holds).
    rng = np.random.default_rng(11)
    for N in (4, 7, 70, 133):
        x = rng.normal(size=(N, 3))
        a0, a1 = (x, np.roll(x, -1, axis=0)) if closed else (x[:-1], x[1:])
        n = a0.shape[0]
        i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        gap = np.abs(i - j) if not closed else np.minimum((i - j) % n, (j - i) % n)
        i, j = i[gap >= 2], j[gap >= 2]
        literal = float(np.sum(np.asarray(topology.solid_angle_literal(a0[i], a1[i], a0[j], a1[j]))))
        assert abs(float(writhe(jnp.asarray(x), closed=closed)) - literal / (4 * np.pi)) < 1e-11, N


def test_small_and_degenerate_polygons():
    # Closed triangle: every pair of edges is adjacent -> 0; open 3-point
    # polyline likewise.  Must be finite, not NaN.
    tri = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.3]])
    assert float(writhe(tri)) == 0.0
    assert float(writhe(tri, closed=False)) == 0.0
    assert np.all(np.isfinite(np.asarray(jax.grad(writhe)(tri))))


def test_writhe_gradient_matches_finite_differences():
    x = random_closed(11, seed=2)
    g = np.asarray(jax.grad(writhe)(jnp.asarray(x)))
    assert np.all(np.isfinite(g))
    h = 1e-6
    fd = np.zeros_like(x)
    for i in range(x.shape[0]):
        for k in range(3):
            e = np.zeros_like(x)
            e[i, k] = h
            fd[i, k] = (float(writhe(x + e)) - float(writhe(x - e))) / (2 * h)
    # Central differences: truncation ~ h^2 |W'''| ~ 1e-12, rounding
    # ~ 1e-16 / h = 1e-10, both well below 1e-6 of the gradient's scale.
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-6 * np.abs(g).max())


def test_writhe_gradient_and_hessian_at_planar_curve():
    # Planar curves are where a twisted ring buckles, and where the literal KL
    # formula (cone times sign) differentiates to 0 instead of the true
    # out-of-plane derivative.  Check gradient and Hessian here too.
    x = wobbly_planar(12)
    g = np.asarray(jax.jit(jax.grad(writhe))(jnp.asarray(x)))
    H = np.asarray(jax.jit(jax.hessian(writhe))(jnp.asarray(x))).reshape(36, 36)
    assert np.all(np.isfinite(g)) and np.all(np.isfinite(H))
    h = 1e-6
    grad = jax.jit(jax.grad(writhe))
    writhe_at = jax.jit(writhe)  # 72 evaluations: compiled once, not operation by operation
    fd_g = np.zeros(36)
    fd_H = np.zeros((36, 36))
    for m in range(36):
        e = np.zeros(36)
        e[m] = h
        e = e.reshape(12, 3)
        fd_g[m] = (float(writhe_at(x + e)) - float(writhe_at(x - e))) / (2 * h)
        fd_H[:, m] = (np.asarray(grad(x + e)) - np.asarray(grad(x - e))).ravel() / (2 * h)
    # The out-of-plane gradient is genuinely non-zero for a non-circular curve.
    assert np.abs(fd_g.reshape(12, 3)[:, 2]).max() > 1e-2
    np.testing.assert_allclose(g.ravel(), fd_g, rtol=0, atol=1e-6 * np.abs(fd_g).max())
    np.testing.assert_allclose(H, fd_H, rtol=0, atol=1e-5 * np.abs(fd_H).max())


# --------------------------------------------------------- linking number
@pytest.mark.parametrize("k", [-2, -1, 0, 1, 3])
def test_ribbon_linking_number_equals_twist(k):
    x, y = ribbon(64, k)
    assert abs(float(linking_number(x, y)) - k) < 1e-10
    assert abs(float(linking_number(y, x)) - k) < 1e-10
    # Planar centreline: Wr = 0 so Lk = Tw = k (Calugareanu).
    assert abs(float(writhe(x))) < 1e-12


def test_hopf_link_symmetric_and_right_hand_rule():
    s = _param(40)
    x = np.stack([np.cos(s), np.sin(s), 0.0 * s], axis=1)
    # y passes downwards (-z) through the disc bounded by the counter-clockwise
    # circle x, against the right-hand-rule normal +z: Lk = -1.
    y = np.stack([1.0 + np.cos(s), 0.0 * s, np.sin(s)], axis=1)
    lxy, lyx = float(linking_number(x, y)), float(linking_number(y, x))
    assert abs(lxy + 1.0) < 1e-12
    assert abs(lxy - lyx) < 1e-12
    # Reversing one component flips the sign.
    assert abs(float(linking_number(x[::-1], y)) - 1.0) < 1e-12


def test_linking_number_far_apart_is_zero():
    rng = np.random.default_rng(7)
    x = rng.normal(size=(23, 3))
    y = rng.normal(size=(31, 3)) + np.array([20.0, 0.0, 0.0])
    lk = float(linking_number(x, y))
    assert abs(lk) < 1e-12


def test_linking_number_torus_link_2_4():
    # Two (1, 2) curves on a torus, half a turn apart in the meridional angle:
    # the (2,4) torus link, each component winding twice about the other.
    def comp(n, j, R=2.0, r=0.7):
        s = _param(n)
        phi = 2 * s + j * np.pi
        rho = R + r * np.cos(phi)
        return np.stack([rho * np.cos(s), rho * np.sin(s), r * np.sin(phi)], axis=1)

    a, b = comp(80, 0), comp(97, 1)
    lab, lba = float(linking_number(a, b)), float(linking_number(b, a))
    assert abs(lab - round(lab)) < 1e-12
    # phi increases from the radial direction towards +z, which is a
    # left-handed turn about the counter-clockwise tangent (v = -z in the
    # ribbon frame): Lk = -2.
    assert abs(lab + 2.0) < 1e-12
    assert abs(lab - lba) < 1e-12


def test_gauss_quadrature_second_order_convergence():
    # Offset eps = 0.3 keeps the integrand smooth on the scale of the segment
    # length already at N = 64 (h = 2 pi / N ~ 0.1 < eps), so the asymptotic
    # regime is reached: the midpoint rule on the inscribed polygon has error
    # C h^2 + O(h^4), and doubling N should divide it by 4 (measured 4.006 and
    # 4.001).  With eps = 0.1 the pre-asymptotic ratio at N = 64 is ~19, hence
    # the choice of eps.  We accept ratios in [3.8, 4.2].
    k = 1
    lk_exact = [float(linking_number(*ribbon(n, k, eps=0.3))) for n in (64, 128, 256)]
    assert np.allclose(lk_exact, k, atol=1e-10)
    err = [abs(float(gauss_linking_quadrature(*ribbon(n, k, eps=0.3))) - k) for n in (64, 128, 256)]
    assert err[2] < err[1] < err[0] < 1e-2
    for coarse, fine in zip(err[:-1], err[1:]):
        assert 3.8 < coarse / fine < 4.2


def test_writhe_quadrature_planar_zero_and_finite_grad():
    x = wobbly_planar(40)
    assert abs(float(writhe_quadrature(x))) < 1e-12
    g = np.asarray(jax.grad(writhe_quadrature)(jnp.asarray(random_closed(15, 4))))
    assert np.all(np.isfinite(g))


def test_eccentric_line():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(9, 3))
    d1 = rng.normal(size=(9, 3))
    d1 /= np.linalg.norm(d1, axis=1, keepdims=True)
    np.testing.assert_allclose(np.asarray(eccentric_line(x, d1, 0.25)), x + 0.25 * d1, atol=0)


@pytest.mark.parametrize("closed", [True, False])
def test_writhe_on_the_host_equals_the_compiled_writhe(closed):
    # a concrete small polygon is summed by NumPy, a traced one by JAX: the same number to roundoff
    for n in (7, 8, 61, topology.HOST_WRITHE_MAX_NODES):
        x = trefoil(n) + 0.01 * np.sin(np.arange(3 * n)).reshape(n, 3)
        host = writhe(x, closed=closed)
        assert isinstance(host, float)
        assert host == pytest.approx(float(jax.jit(writhe, static_argnames="closed")(x, closed=closed)), abs=1e-13)
    big = trefoil(topology.HOST_WRITHE_MAX_NODES + 1)
    assert isinstance(writhe(big, closed=closed), jax.Array)  # above the limit: the compiled sum
