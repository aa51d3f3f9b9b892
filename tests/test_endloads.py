"""Rods under end loads (issue 19): end shortening, tension, end rotation.

Validated against the localized helical buckle of Neukirch, van der Heijden and Thompson (2002,
eqs. 14-15): for (m, t, gamma) the analytic end rotation R and end shortening d are imposed on the
discrete clamped rod, which is solved by Newton from the analytic centreline; its end moment M and
tension T (exact derivatives of the energy) must give back m = M L/B and t = T L^2/B. The discrete
error is O(h^2) with a large constant (the loop's core is L/lambda wide): measured at N = 120 and
240 (benchmarks/helical_buckling.py has N = 480 too), Richardson's extrapolation of the two meets
1e-3. Infinite-rod formulas: lambda = sqrt(t - m^2/4) >= 14 keeps the finite-length error
(~ e^-lambda) out of the way; D/L = 2e-4 keeps the stretch (T/EA = t (D/L)^2 / 16 < 1e-6) out.
"""
import math

import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod.studies import endloads as el
from jaxrod.model.material import Material
from jaxrod.model.topology import writhe

NS = (120, 240)
# (m, t, nu): lambda = 14.1 and 16.6; theta_max = 109 and 147 degrees; gamma = 2/3 and 1
SETS = ((20.0, 300.0, 0.5), (10.0, 300.0, 0.0))
D_OVER_L = 2e-4
NO_STABILITY = el.EndLoadOptions(with_stability=False)


def _rod(N, nu, d, contact=None):
    return el.shortened_rod(N, 1.0, Material.from_ratio(B=1.0, nu=nu, D=D_OVER_L), shortening=d,
                            contact_stiffness=contact)


@pytest.fixture(scope="module")
def helices():
    out = {}
    for N in NS:
        for (m, t, nu) in SETS:
            ref = el.localized_helix(m, t, 1.0 / (1.0 + nu))
            rod = _rod(N, nu, ref.d)
            e = el.solve(rod, ref.R, el.helical_start(rod, m, t, ref.R), el.EndLoadOptions(k=4))
            out[N, m] = (ref, rod, e, el.end_loads(rod, e.q, ref.R, e.neighbourhood))
    return out


def test_analytic_helix_is_self_consistent():
    """The closed-form theta(s), integrated (``localized_helix_curve``), has the end shortening d,
    the largest angle theta_max and the writhe (of the curve with long straight tails) that
    eqs. 14-15 give; and the inverse map (d, R, gamma) -> (m, t) finds (m, t) back."""
    m, t, gamma = 20.0, 300.0, 2.0 / 3.0
    ref = el.localized_helix(m, t, gamma)
    s = np.linspace(-2.0, 2.0, 2001)
    theta, _, r = el.localized_helix_curve(m, t, s)
    span = r[-1, 2] - r[0, 2]
    assert abs((s[-1] - s[0] - span) - ref.d) < 1e-9
    assert abs(theta.max() - ref.theta_max) < 1e-4  # the grid's nearest point to the peak
    far = 1e4  # rays: the ray-closed writhe to O(L / far)
    ext = np.concatenate([[r[0] - [0, 0, far]], r, [r[-1] + [0, 0, far]]])
    assert abs(float(writhe(jnp.asarray(ext), closed=False)) - ref.Wr) < 1e-3  # polygon of 4000 edges
    back = el.localized_helix_from_shortening(ref.d, ref.R, gamma)
    assert any(abs(h.m - m) < 1e-9 * m and abs(h.t - t) < 1e-9 * t for h in back)


def test_end_loads_match_nvdht_after_richardson(helices):
    """m and t to 1e-3 relative, theta_max to 1e-3 rad, from N = 120 and 240 (O(h^2))."""
    r = (NS[1] / NS[0]) ** 2
    for (m, t, nu) in SETS:
        (ref, _, e1, l1), (_, _, e2, l2) = helices[NS[0], m], helices[NS[1], m]
        assert e1.solution.converged and e2.solution.converged
        m_h = [l.M for l in (l1, l2)]
        t_h = [l.T for l in (l1, l2)]
        th_h = [el.tangent_angles(e.x).max() for e in (e1, e2)]
        extrapolate = lambda a: (r * a[1] - a[0]) / (r - 1.0)  # noqa: E731
        assert abs(extrapolate(m_h) / m - 1.0) < 1e-3, (m, m_h)
        assert abs(extrapolate(t_h) / t - 1.0) < 1e-3, (t, t_h)
        # the largest sampled angle (edge midpoints): 1e-3 rad after extrapolation (measured 1.0e-3, 3e-4)
        assert abs(extrapolate(th_h) - ref.theta_max) < 2e-3
        # second order: the error shrinks by ~4 from N = 120 to 240 (measured 3.9 to 4.2)
        for a, exact in ((m_h, m), (t_h, t)):
            ratio = (a[0] - exact) / (a[1] - exact)
            assert 3.0 < ratio < 5.0, (a, exact, ratio)


def test_envelope_error_falls_with_N(helices):
    for (m, t, nu) in SETS:
        errs = [el.envelope_error(helices[N, m][2].x, m, t) for N in NS]
        assert errs[1] < errs[0] / 2.5, errs


def test_linking_number_twist_moment_and_stability(helices):
    """Lk = Wr + Tw = R / 2 pi to roundoff; the twisting moment C * twist per length is M (the
    twist equation makes it uniform); the stability is reported with the axial rotation (an
    exact symmetry of coaxial clamps) removed."""
    for (N, m), (ref, rod, e, loads) in helices.items():
        assert abs(e.Lk - ref.R / (2 * math.pi)) < 1e-10
        assert abs(loads.M_twist - loads.M) < 1e-9 * abs(loads.M)
        assert e.stability.n_zero_modes == 1
        assert abs(e.Wr - ref.Wr) < 0.05  # the loop's writhe, finite rod and discrete
    # measured Morse indices: 1 for both sets (the centred loop under rigid loading, a saddle)
    assert all(e.stability.n_negative == 1 for (_, _, e, _) in helices.values())


def test_end_loads_are_derivatives_of_the_equilibrium_energy(helices):
    """T = -dE/d(shortening) and M = dE/dphi along the equilibria (envelope theorem), by central
    differences of re-solved equilibria."""
    m, t, nu = SETS[0]
    ref, rod, e, loads = helices[NS[0], m]
    # steps: small enough for the curvature of E (T ~ d^-2: 1e-4 in d), large enough for the
    # solves' gradient tolerance (1e-8, near the stiff stretch's roundoff)
    h = 1e-4
    energies = []
    for ds in (-h, h):
        r2 = el.with_shortening(rod, ref.d + ds)
        energies.append(el.solve(r2, ref.R, e.q, NO_STABILITY).energy)
    assert abs(-(energies[1] - energies[0]) / (2 * h) / loads.T - 1.0) < 1e-6
    h = 1e-3
    energies = [el.solve(rod, ref.R + dp, e.q, NO_STABILITY).energy for dp in (-h, h)]
    assert abs((energies[1] - energies[0]) / (2 * h) / loads.M - 1.0) < 1e-6


def test_force_control_reproduces_the_displacement_controlled_state(helices):
    """Under the dead load T measured at the imposed shortening, the force-controlled rod (end
    sliding on the axis) is in equilibrium at the same shape: its extension is minus the
    shortening and its moment M."""
    m, t, nu = SETS[0]
    ref, rod, e, loads = helices[NS[0], m]
    fr = el.ForceLoadedRod(rod, "slide")
    f = fr.solve(loads.T, ref.R, fr.u_from(e.q, -ref.d * np.asarray(rod.axis)))
    assert f.converged and f.grad_norm <= 1e-8
    assert abs(f.extension + ref.d) < 1e-9 and abs(f.M / loads.M - 1.0) < 1e-9
    assert abs(f.Lk - ref.R / (2 * math.pi)) < 1e-10
    assert f.morse >= e.stability.n_negative  # a dead load constrains less than fixed ends (measured 1 and 1)
    # the Hessian Newton uses (rod block and end rows composed on the host from the rod's compiled
    # pieces) against central differences of the gradient, for the sliding end and the end free in
    # space (whose solve benchmarks/helical_buckling.py checks), off equilibrium
    rng = np.random.default_rng(1)
    for end in ("slide", "free"):
        fe = el.ForceLoadedRod(rod, end)
        u = fe.u_from(e.q, np.array([2e-3, -1e-3, -ref.d])) + 1e-3 * rng.standard_normal(rod.n_dof + fe.k)
        args = (ref.R, loads.T, fe.neighbourhood(u, ref.R))
        h, z = fe.hessian(u, args)
        v = rng.standard_normal(u.size)
        eps = 1e-6
        fd = (fe.value_and_grad(u + eps * v, args)[1] - fe.value_and_grad(u - eps * v, args)[1]) / (2 * eps)
        assert np.max(np.abs(fd - h @ v)) < 1e-6 * np.max(np.abs(h @ v)), end
        # the zero mode: the energy is invariant under the rotation about the axis
        assert abs(fe.value_and_grad(u, args)[1] @ z[:, 0]) < 1e-9 * np.linalg.norm(z)


def test_straight_rod_buckling_moment_under_tension():
    """The straight clamped rod under tension T buckles at the continuum moment of the clamped
    problem (``clamped_tension_twist_threshold``, O(h^2)), which tends to Greenhill's
    8.9868 B/L as T -> 0 and to 2 sqrt(BT) as L sqrt(T/B) grows."""
    assert abs(el.clamped_tension_twist_threshold(1.0, 1e-6, 1.0) - 8.98681892) < 1e-5
    rod = _rod(NS[0], 0.5, 0.0)
    ratios = []
    for t in (10.0, 100.0):
        exact = el.clamped_tension_twist_threshold(1.0, t, 1.0)
        _, Mc = el.straight_buckling_moment(rod, t)
        assert abs(Mc / exact - 1.0) < 2e-3, (t, Mc, exact)  # measured 5.7e-4 and 1.1e-3 at N = 120
        ratios.append(exact / el.tension_twist_threshold(1.0, t))
    assert ratios[0] > ratios[1] > 1.0  # 1.649, 1.049


def test_bad_input_is_refused_naming_the_parameter():
    """Each refusal is one ValueError naming the parameter (issue 19, acceptance 5)."""
    mat = Material.from_ratio(B=1.0, nu=0.5, D=0.01)
    rod = el.shortened_rod(20, 1.0, mat)
    fr = el.ForceLoadedRod(rod)
    q0 = np.asarray(rod.q_init)
    ref = el.localized_helix(20.0, 300.0, 2.0 / 3.0)  # R = 33.8 rad (5.4 turns), lambda = 14.1
    bad = [
        ("shortening", lambda: el.shortened_rod(20, 1.0, mat, shortening=1.0)),  # end shortening >= L
        ("shortening", lambda: el.shortened_rod(20, 1.0, mat, shortening=-0.1)),
        ("shortening", lambda: el.shortened_rod(20, 1.0, mat, shortening=float("nan"))),
        ("N must", lambda: el.shortened_rod(3, 1.0, mat)),
        ("length", lambda: el.shortened_rod(20, 0.0, mat)),
        ("contact_stiffness", lambda: el.shortened_rod(20, 1.0, mat, contact_stiffness=-1.0)),
        ("T must be positive", lambda: fr.solve(0.0, 0.0, fr.straight(1.0))),  # non-positive force
        ("T must be positive", lambda: fr.solve(-2.0, 0.0, fr.straight(1.0))),
        ("T must be finite", lambda: fr.solve(float("inf"), 0.0, fr.straight(1.0))),
        ("phi", lambda: fr.solve(1.0, float("nan"), fr.straight(1.0))),
        ("u0", lambda: fr.solve(1.0, 0.0, np.full(rod.n_dof + 1, np.nan))),
        ("end must be", lambda: el.ForceLoadedRod(rod, "fixed")),
        ("phi", lambda: el.solve(rod, float("nan"), q0)),
        ("q0", lambda: el.solve(rod, 0.0, np.full_like(q0, np.inf))),
        ("q0", lambda: el.solve(rod, 0.0, q0[:-1])),
        ("gtol", lambda: el.solve(rod, 0.0, q0, el.EndLoadOptions(gtol=-1.0))),
        ("max_step", lambda: el.EndLoadOptions(max_step=0.0)),
        ("max_steps", lambda: el.EndLoadOptions(max_steps=-1)),
        ("phi", lambda: el.end_loads(rod, q0, float("inf"))),
        ("m\\^2 < 4 t", lambda: el.localized_helix(10.0, 20.0, 1.0)),
        ("m must be finite", lambda: el.localized_helix(float("nan"), 20.0, 1.0)),
        ("t must be positive", lambda: el.localized_helix(1.0, -20.0, 1.0)),
        ("gamma", lambda: el.localized_helix(1.0, 20.0, 0.0)),
        ("d must be positive", lambda: el.localized_helix_from_shortening(-0.1, 30.0, 1.0)),
        ("d \\(end shortening / L\\) must be below 1", lambda: el.localized_helix_from_shortening(1.0, 30.0, 1.0)),
        ("R must be finite", lambda: el.localized_helix_from_shortening(0.2, float("nan"), 1.0)),
        ("T must be positive", lambda: el.straight_buckling_moment(rod, 0.0)),
        ("L must be positive", lambda: el.clamped_tension_twist_threshold(1.0, 1.0, -1.0)),
        # too few nodes for the turns asked: the loop's core (6 edges per L / lambda) or the twist (pi/2 rad per edge)
        ("N = 30 is too few", lambda: el.check_helix_resolution(30, 20.0, 300.0, 33.8)),
        ("N = 20 is too few", lambda: el.helical_start(rod, 20.0, 300.0, ref.R)),
        ("N = 20 is too few", lambda: el.solve(rod, ref.R, q0)),
        ("N = 20 is too few", lambda: fr.solve(1.0, ref.R, fr.straight(1.0))),
    ]
    for match, call in bad:
        with pytest.raises(ValueError, match=match):
            call()
    # the limits themselves: pi/2 rad per edge and 6 edges per core width, N = need passes
    assert el.check_rotation_resolution(24, ref.R) == 24
    with pytest.raises(ValueError, match="N >= 24"):
        el.check_rotation_resolution(23, ref.R)
    assert el.check_helix_resolution(87, 20.0, 300.0, ref.R) == 87
    with pytest.raises(ValueError, match="N >= 87"):
        el.check_helix_resolution(86, 20.0, 300.0, ref.R)


@pytest.mark.parametrize("quadrature", [2, 3])
def test_contact_hessian_of_a_pair_at_a_clamp(quadrature):
    """Clamped nodes have no DOFs (index -1 in the Hessian pattern): a contact pair whose segment
    touches a clamp (here edge 1, nodes 1 (clamped) and 2 (free), against a node of the middle
    of the rod) must add only its free rows and columns. Structured Hessian against jax.hessian
    of the same energy."""
    import jax

    from jaxrod.model.hessian import dense_autodiff_hessian, scaled_hessian

    N, D = 12, 0.1
    rod = el.shortened_rod(N, 1.0, Material.from_ratio(B=1.0, nu=0.5, D=D), shortening=0.3, contact_stiffness=10.0,
                           contact_quadrature=quadrature)
    q = np.asarray(rod.q_init).copy()
    x = np.asarray(rod.nodes(jnp.asarray(q)))
    # node 7 brought back beside the midpoint of edge 1 (0.7 D away), nodes 6 and 8 beside it
    target = 0.5 * (x[1] + x[2]) + np.array([0.7 * D, 0.0, 0.0])
    for k, dz in ((6, -0.08), (7, 0.0), (8, 0.08)):
        q[3 * (k - 2):3 * (k - 1)] = target + np.array([0.02 * (k - 7) ** 2, 0.03 * (k - 7), dz])
    q[3 * (N - 4):] = 0.1 * np.arange(N - 3)
    nbr = rod.neighbourhood(q, 0.4)
    u = rod.to_scaled(q)
    e_contact = float(rod.energy_terms(jnp.asarray(q), 0.4, nbr)["contact"])
    assert e_contact > 0.0  # the pair is in contact
    fast = np.asarray(jax.jit(scaled_hessian)(rod, jnp.asarray(u), 0.4, nbr))  # eager: one program per operation
    ref = np.asarray(jax.jit(dense_autodiff_hessian)(rod, jnp.asarray(u), 0.4, nbr))
    assert np.max(np.abs(fast - ref)) < 1e-11 * np.max(np.abs(ref)), np.unravel_index(np.argmax(np.abs(fast - ref)), ref.shape)
    # the scene's quadrature is the one both use (3 Gauss points per segment: another energy)
    from jaxrod.model.contact import contact_energy

    pairs, mask = rod.contact_candidates(nbr)
    x = rod.nodes(jnp.asarray(q))
    by_points = {k: float(contact_energy(x, pairs, mask, False, D, 1.0, 10.0, k)) for k in (2, 3)}
    assert e_contact == pytest.approx(by_points[quadrature], rel=1e-13)
    assert abs(by_points[2] - by_points[3]) > 1e-6 * by_points[3]


def test_contact_quadrature_is_refused_unless_1_2_or_3():
    with pytest.raises(ValueError, match="contact_quadrature"):
        el.shortened_rod(12, 1.0, Material.from_ratio(B=1.0, nu=0.5, D=0.1), contact_stiffness=10.0,
                         contact_quadrature=4)


def test_cli_helix(helices, tmp_path, capsys):
    """`jaxrod helix`: the files and the summary, in process (the fixture's compiled programs:
    same N, material and slenderness); bad flags exit 2 with one line naming the flag."""
    import csv
    import json

    from jaxrod.cli import main

    out = tmp_path / "helix"
    assert main(["helix", "--m", "20", "--t", "300", "--nu", "0.5", "--N", str(NS[0]), "--out", str(out),
                 "--json", "--quiet", "--no-cache"]) == 0
    res = json.loads(capsys.readouterr().out)
    ref, rod, e, loads = helices[NS[0], 20.0]
    # the same equilibrium, reached through stiffening stages (``solve_from_helix``): equal to Newton's tolerance
    assert abs(res["M"] - loads.M) < 1e-6 * abs(loads.M) and abs(res["T"] - loads.T) < 1e-6 * loads.T
    assert res["m_analytic"] == ref.m and res["t_analytic"] == ref.t and res["morse"] == 1
    assert abs(res["Lk"] - ref.R / (2 * math.pi)) < 1e-10
    assert abs(res["envelope_L1"] - el.envelope_error(e.x, 20.0, 300.0)) < 1e-7
    assert res["centreline_max_distance"] < 0.05  # the computed loop turned onto the analytic one (L = 1)
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["centreline.csv", "centreline.png", "envelope.csv",
                                                     "envelope.png", "helix.json"]
    with open(out / "envelope.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == NS[0] - 1 and abs(max(float(r["theta_analytic"]) for r in rows) - ref.theta_max) < 1e-3
    for argv, flag in ((["--m", "20", "--t", "300", "--N", "60"], "--N = 60 is too few"),
                       (["--m", "20"], "give either --m and --t"),
                       (["--d", "1.5", "--R", "3"], "--d \\(end shortening / L\\) must be below 1"),
                       (["--m", "20", "--t", "-3"], "--t must be positive"),
                       (["--m", "20", "--t", "300", "--nu", "0.7"], "--nu")):
        assert main(["helix", *argv, "--quiet", "--no-cache"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and __import__("re").search(flag, err[0]), err


def test_plectoneme_plateau_two_phase_model():
    """The hard-contact two-phase plectoneme (``plectoneme_plateau``): at its torque and helix
    angle the plectoneme's energy per length, B sin^4 a / 2r^2 - M sin 2a / 2r, equals the straight
    phase's -T and is stationary in a (coexistence); the small-T limit
    M -> 2 (2/3)^(3/4) B^(1/4) T^(3/4) r^(1/2); the plateau lies below the buckling torque 2 sqrt(BT)
    for a thin rod; slope = -1 / (writhe per length)."""
    B, T, D = 1.0, 400.0, 0.015
    p = el.plectoneme_plateau(B, T, D)
    g = lambda a: B * math.sin(a) ** 4 / (2 * p.r ** 2) - p.M * math.sin(2 * a) / (2 * p.r)  # noqa: E731
    assert abs(g(p.alpha) + T) < 1e-9 * T
    h = 1e-6
    assert abs((g(p.alpha + h) - g(p.alpha - h)) / (2 * h)) < 1e-5 * T
    assert p.M < 2 * math.sqrt(B * T)
    assert abs(p.slope * p.writhe_per_length + 1.0) < 1e-12
    small = el.plectoneme_plateau(B, 1e-4, D)
    approx = 2 * (2 / 3) ** 0.75 * B ** 0.25 * 1e-4 ** 0.75 * (D / 2) ** 0.5
    assert abs(small.M / approx - 1) < 1e-3
    with pytest.raises(ValueError, match="D"):
        el.plectoneme_plateau(B, T, 0.0)
