"""jaxrod.continuation.arclength on small gradient systems whose folds, branch points and branches are known
in closed form (issue 17, acceptance 9, first part: each event type on an analytic system)."""
import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod.continuation import ContinuationOptions
from jaxrod.continuation.arclength import (BifurcationProblem, ContinuationError, PseudoArclength, Result,
                                continuation, emanating_directions, fold_at, fold_curve, fold_sensitivity,
                                switch_branches)
from jaxrod.continuation.arclength.locate import FOLD_QUADRATIC_ITERATIONS

ALG = PseudoArclength()


def bordered_det_sign(prob, point):
    F, J, Fp = prob.linearise(point.u, point.p, prob.args)
    t = point.tangent
    M = jnp.block([[J, Fp[:, None]], [t[None, :-1], jnp.reshape(t[-1], (1, 1))]])
    return int(np.sign(np.linalg.det(np.asarray(M))))


def check_located(e, kind, p, u, tol=1e-12):
    assert e.kind == kind and e.converged
    assert abs(e.p - p) <= tol and np.max(np.abs(e.u - np.asarray(u))) <= tol
    assert e.critical_eigenvalue <= 1e-10 and e.residual <= 1e-10


# 1. Fold: E = x^3/3 - p x + y^2/2, branches x = +-sqrt(p), fold at (0, 0), p = 0
def fold_energy(u, p, mu):
    x, y = u
    return x ** 3 / 3 - p * x + mu * x ** 2 / 2 + y ** 2 / 2


@pytest.fixture(scope="module")
def fold_problem():
    return BifurcationProblem(fold_energy, [1.0, 0.0], 1.0, 0.0)


@pytest.mark.parametrize("ds, u0, p0, morse", [(-0.1, [1.0, 0.0], 1.0, (0, 1)), (-0.13, [1.0, 0.0], 1.0, (0, 1)),
                                               (-0.1, [-1.1, 0.0], 1.21, (1, 0))])
def test_fold_through_onto_unstable_branch(fold_problem, ds, u0, p0, morse):
    prob = BifurcationProblem(fold_energy, u0, p0, 0.0) if p0 != 1.0 else fold_problem
    seen = []
    br = continuation(prob, ALG, ContinuationOptions(ds=ds, p_min=-1.0, p_max=1.3, k=1), observer=seen.append)
    assert br.result is Result.BOUNDARY and len(seen) == len(br.points) - 1
    assert all(q is r for q, r in zip(seen, br.points[1:]))  # the observer saw every accepted point
    (e,) = br.events
    check_located(e, "fold", 0.0, [0.0, 0.0])  # p* to 1e-12, whatever ds and start
    assert (e.morse_before, e.morse_after) == morse and e.iterations <= 6
    x, y = br.u.T
    assert np.max(np.abs(x ** 2 - br.p)) <= 1e-10 and np.max(np.abs(y)) <= 1e-12
    assert np.all(br.morse_index == np.where(x > 0, 0, 1))  # through the fold onto the unstable branch
    assert x.min() < -1 and x.max() > 0.99  # both branches, p up to the bound
    # bordered determinant: det J / t_p keeps its sign through a fold
    signs = [q.bordered_sign for q in br.points]
    assert len(set(signs)) == 1 and signs == [bordered_det_sign(prob, q) for q in br.points]


# 2. Simple branch points: E = x^4/4 - p x^2/2 + (y - p)^2/2 + x^2 y^2/2. Trivial branch (0, p) with
# lambda = p^2 - p: branch points at p = 0 (index 0 -> 1) and p = 1 (1 -> 0). From p = 0:
# x^2 = y, p = y + y^2, stable up to p = 2; from p = 1: y = 1, x^2 = p - 1, index 1 up to p = 2,
# where the two cross (a transcritical, non-symmetric branch point at x = +-1, y = 1).
def pitchfork_energy(u, p, args):
    x, y = u
    return x ** 4 / 4 - p * x ** 2 / 2 + (y - p) ** 2 / 2 + x ** 2 * y ** 2 / 2


@pytest.fixture(scope="module")
def pitchfork():
    prob = BifurcationProblem(pitchfork_energy, [0.0, -0.5], -0.5)
    return prob, continuation(prob, ALG, ContinuationOptions(ds=0.1, p_max=1.5))


def test_simple_branch_points_on_trivial_branch(pitchfork):
    prob, br = pitchfork
    e0, e1 = br.events
    check_located(e0, "branch_point", 0.0, [0.0, 0.0])
    check_located(e1, "branch_point", 1.0, [0.0, 1.0])
    assert (e0.multiplicity, e0.morse_before, e0.morse_after) == (1, 0, 1)
    assert (e1.multiplicity, e1.morse_before, e1.morse_after) == (1, 1, 0)
    assert np.all(br.morse_index == ((br.p > 0) & (br.p < 1)))
    signs = np.array([q.bordered_sign for q in br.points])  # the classic test changes sign at each
    assert np.count_nonzero(np.diff(signs)) == 2
    assert list(signs) == [bordered_det_sign(prob, q) for q in br.points]
    # another step and start: the same points
    other = continuation(prob, ALG, ContinuationOptions(ds=0.07, p_max=1.5), start=([0.0, -0.37], -0.37, [0, 1, 1]))
    assert np.allclose([e.p for e in other.events], [0.0, 1.0], rtol=0, atol=1e-12)


def test_switch_at_simple_branch_points(pitchfork):
    prob, br = pitchfork
    e0, e1 = br.events
    (d0,) = emanating_directions(prob, e0)
    assert d0.order == 3 and abs(d0.kappa + 1) <= 1e-10 and d0.predicted_morse == (0, 0)  # p = x^2 + O(x^4)
    opts = ContinuationOptions(ds=0.05, p_min=-1.0, p_max=3.0)
    from_zero = switch_branches(prob, e0, ALG, opts)
    assert len(from_zero) == 2 and {b.origin["sign"] for b in from_zero} == {1, -1}
    for b in from_zero:
        x, y = b.u.T
        assert np.all(np.sign(x) == b.origin["sign"])
        assert np.max(np.abs(x ** 2 - y)) <= 1e-10 and np.max(np.abs(b.p - y - y ** 2)) <= 1e-10
        assert np.all(b.morse_index == (b.p > 2))  # stable up to the secondary branch point
        (e,) = b.events
        check_located(e, "branch_point", 2.0, [b.origin["sign"], 1.0])  # transcritical: unfolded system
        assert (e.morse_before, e.morse_after) == (0, 1)
    (d1,) = emanating_directions(prob, e1)
    assert d1.predicted_morse == (1, 1)
    for b in switch_branches(prob, e1, ALG, opts):
        x, y = b.u.T
        assert np.max(np.abs(y - 1)) <= 1e-10 and np.max(np.abs(x ** 2 - (b.p - 1))) <= 1e-10
        assert np.all(b.morse_index == (b.p < 2))
        check_located(b.events[0], "branch_point", 2.0, [np.sign(x[0]), 1.0])
    # at the transcritical point p = 2 the reduced equation is quadratic; the other branch is
    # y = 1, x^2 = p - 1 (index 1 below p = 2). Followed down, it turns back in p at x = 0, p = 1:
    # no fold (F_p is orthogonal to the kernel) but the branch point of the trivial branch.
    e2 = from_zero[0].events[0]
    (d2,) = emanating_directions(prob, e2)
    # the kernel vector's sign is arbitrary (an eigenvector), and predicted_morse is (r > 0, r < 0)
    # along it: each prediction must match the branch followed that way
    assert d2.order == 2 and sorted(d2.predicted_morse) == [0, 1]
    along = switch_branches(prob, e2, ALG, opts, directions=[d2])
    assert [b.morse_index[0] for b in along] == list(d2.predicted_morse)
    down, up = sorted(along, key=lambda b: b.p.min())
    for b, morse in ((down, 1), (up, 0)):
        x, y = b.u.T
        assert np.max(np.abs(y - 1)) <= 1e-10 and np.max(np.abs(x ** 2 - (b.p - 1))) <= 1e-10
        assert np.all(b.morse_index[b.p < 1.95] == 1) and np.all(b.morse_index[b.p > 2.05] == 0)
        assert b.morse_index[0] == morse
    assert up.p.min() > 2 and not up.events
    turn = down.events[0]
    check_located(turn, "branch_point", 1.0, [0.0, 1.0])
    assert (turn.morse_before, turn.morse_after) == (1, 1) and down.u[:, 0].min() < -1  # on through x = 0


# 3. Double branch point, D4 symmetry: E = x^4/4 + y^4/4 + a x^2 y^2/2 - p r/2 + z^2/2 + z r/2,
# r = x^2 + y^2. z = -r/2 eliminates to (x^4/4 + y^4/4 + (2a-1) x^2 y^2/2)/2 - p r/2: branches on the
# axes (x^2 = 2p, stable iff a > 1) and the diagonals (x^2 = y^2 = p/a, stable iff a < 1). The z r
# coupling makes the range correction of the reduced quartic nonzero (-1/8 on the unit circle).
def d4_energy(u, p, a):
    x, y, z = u
    r = x ** 2 + y ** 2
    return x ** 4 / 4 + y ** 4 / 4 + a * x ** 2 * y ** 2 / 2 - p * r / 2 + z ** 2 / 2 + z * r / 2


@pytest.mark.parametrize("a", [3.0, 0.5])
def test_double_branch_point(a):
    prob = BifurcationProblem(d4_energy, [0.0, 0.0, 0.0], -0.3, a)
    br = continuation(prob, ALG, ContinuationOptions(ds=0.1, p_max=0.5))
    (e,) = br.events
    check_located(e, "branch_point", 0.0, [0.0, 0.0, 0.0])
    assert (e.multiplicity, e.morse_before, e.morse_after) == (2, 0, 2) and e.v.shape == (3, 2)
    assert len({q.bordered_sign for q in br.points}) == 1  # two eigenvalues cross: no sign change
    dirs = emanating_directions(prob, e)
    axis_morse, diag_morse = (0, 1) if a > 1 else (1, 0)
    kinds = []
    for d in dirs:  # the reduced cubic's solutions: the two axes and the two diagonals
        w = np.abs(d.vector[:2])
        assert d.isolated and d.order == 3 and abs(d.vector[2]) <= 1e-12
        diagonal = abs(w[0] - w[1]) <= 1e-10
        assert diagonal or min(w) <= 1e-10
        kinds.append(diagonal)
        # dp = -kappa r^2: r^2 = x^2 = 2 dp on an axis, r^2 = 2 x^2 = 2 dp / a on a diagonal
        assert abs(-1 / d.kappa - (2 / a if diagonal else 2.0)) <= 1e-10
        assert d.predicted_morse == ((diag_morse,) * 2 if diagonal else (axis_morse,) * 2)
    assert sorted(kinds) == [False, False, True, True]
    branches = switch_branches(prob, e, ALG, ContinuationOptions(ds=0.05, p_min=-1.0, p_max=0.5), directions=dirs)
    assert len(branches) == 8
    for b in branches:
        x, y, z = b.u.T
        assert b.result is Result.BOUNDARY and not b.events and b.p.min() > 0
        assert np.max(np.abs(z + (x ** 2 + y ** 2) / 2)) <= 1e-10
        if kinds[[id(d) for d in dirs].index(id(b.origin["direction"]))]:
            assert np.max(np.abs(x ** 2 - b.p / a)) <= 1e-10 and np.max(np.abs(x ** 2 - y ** 2)) <= 1e-10
            assert np.all(b.morse_index == diag_morse)
        else:
            assert np.max(np.abs(x ** 2 + y ** 2 - 2 * b.p)) <= 1e-10 and np.max(np.abs(x * y)) <= 1e-10
            assert np.all(b.morse_index == axis_morse)


def test_o2_circle_of_solutions_is_flagged():
    # isotropic quartic: every kernel direction is a branch (a circle, with a rotation zero mode)
    prob = BifurcationProblem(d4_energy, [0.0, 0.0, 0.0], -0.3, 1.0)
    (e,) = continuation(prob, ALG, ContinuationOptions(ds=0.1, p_max=0.3)).events
    assert e.multiplicity == 2
    dirs = emanating_directions(prob, e)
    assert len(dirs) == 2 and not any(d.isolated for d in dirs)



def test_split_pair_inside_one_step_gives_two_simple_branch_points():
    # a broken D4 symmetry: the pair crosses at p = 0 and p = delta, both inside one step
    delta = 0.02

    def energy(u, p, delta):
        x, y, z = u
        quartic = x ** 4 / 4 + y ** 4 / 4 + 3 * x ** 2 * y ** 2 / 2
        return quartic - p * x ** 2 / 2 - (p - delta) * y ** 2 / 2 + z ** 2 / 2

    prob = BifurcationProblem(energy, [0.0, 0.0, 0.0], -0.3, delta)
    e0, e1 = continuation(prob, ALG, ContinuationOptions(ds=0.1, p_max=0.3)).events
    assert e0.step == e1.step  # the Morse index went 0 -> 2 in one step
    check_located(e0, "branch_point", 0.0, [0.0, 0.0, 0.0])
    check_located(e1, "branch_point", delta, [0.0, 0.0, 0.0])
    assert [(e.multiplicity, e.morse_before, e.morse_after) for e in (e0, e1)] == [(1, 0, 1), (1, 1, 2)]
    assert abs(e0.v[0, 0]) == 1.0 and abs(e1.v[1, 0]) == 1.0


# 4. Imperfect pitchfork: + eps x unfolds the branch point into a fold at x = (eps/2)^(1/3), p = 3 x^2
def test_imperfect_bifurcation_fold():
    eps = 1e-3

    def energy(u, p, eps):
        x, y = u
        return x ** 4 / 4 - p * x ** 2 / 2 + y ** 2 / 2 + x ** 2 * y ** 2 / 2 + eps * x

    prob = BifurcationProblem(energy, [1.0, 0.0], 1.0, eps)
    br = continuation(prob, ALG, ContinuationOptions(ds=-0.1, p_max=1.0))
    (e,) = br.events
    xf = (eps / 2) ** (1 / 3)
    check_located(e, "fold", 3 * xf ** 2, [xf, 0.0])
    assert (e.morse_before, e.morse_after) == (0, 1)
    x = br.u[:, 0]
    assert np.max(np.abs(x ** 3 - br.p * x + eps)) <= 1e-10 and np.all(br.morse_index == (x < xf))


# 5. Fold curve: E = x^3/3 - p x + mu x^2/2 + y^2/2 folds at x = -mu/2, p* = -mu^2/4
def test_fold_curve_in_second_parameter():
    mu0 = 0.3
    prob = BifurcationProblem(fold_energy, [1.0, 0.0], 1.0, mu0)
    (fold,) = continuation(prob, ALG, ContinuationOptions(ds=-0.1, p_max=1.2)).events
    check_located(fold, "fold", -mu0 ** 2 / 4, [-mu0 / 2, 0.0])
    reached = []
    for ds in (0.1, -0.1):
        c = fold_curve(prob, fold, lambda args, mu: mu, mu0, ALG, ContinuationOptions(ds=ds, p_min=-1.0, p_max=1.0))
        assert c.result is Result.BOUNDARY and len(c.mu) >= 5
        assert np.max(np.abs(c.p + c.mu ** 2 / 4)) <= 1e-10
        assert np.max(np.abs(c.u[:, 0] + c.mu / 2)) <= 1e-10
        assert np.max(np.abs(c.dp_dmu + c.mu / 2)) <= 1e-10  # implicit function theorem
        assert np.max(c.residual) <= 1e-10 and np.allclose(np.abs(c.v[:, 0]), 1.0)
        reached.append(c.mu[-1])
    assert reached[0] >= 1.0 and reached[1] <= -1.0
    # the fold's sensitivity (one bordered solve at the located fold) and the fold at another mu
    # (Newton on the fold system at fixed mu): p* = -mu^2/4, dp*/dmu = -mu/2, u* = (-mu/2, 0)
    set_mu = lambda args, mu: mu  # noqa: E731
    assert abs(fold_sensitivity(prob, fold, set_mu, mu0) + mu0 / 2) <= 1e-10
    moved = fold_at(prob, fold, set_mu, mu0, 0.8, ContinuationOptions())
    assert moved.converged and moved.residual <= 1e-10 and moved.iterations <= FOLD_QUADRATIC_ITERATIONS
    assert abs(moved.p + 0.8 ** 2 / 4) <= 1e-12 and abs(moved.dp_dmu + 0.4) <= 1e-12
    assert np.max(np.abs(moved.u - [-0.4, 0.0])) <= 1e-12 and abs(abs(moved.v[0]) - 1.0) <= 1e-12


# Failures are reported, not hidden. E = x^2/2 - p x - (2/3)(1 - x)^(3/2) + y^2/2: the branch
# p = x + sqrt(1 - x) folds at x = 3/4, p = 5/4 and ends at (x, p) = (1, 1) (F not smooth there).
def ending_energy(u, p, args):
    x, y = u
    return x ** 2 / 2 - p * x - (2 / 3) * (1 - x) ** 1.5 + y ** 2 / 2


def test_corrector_failure_is_reported():
    prob = BifurcationProblem(ending_energy, [0.0, 0.0], 1.0)
    br = continuation(prob, ALG, ContinuationOptions(ds=0.1), throw=False)
    assert br.result is Result.CORRECTOR_FAILED and "ds_min" in br.message
    assert br.u[-1, 0] > 0.99 and abs(br.p[-1] - 1) < 0.01  # got to the end of the branch
    (e,) = br.events
    check_located(e, "fold", 1.25, [0.75, 0.0])
    with pytest.raises(ContinuationError, match="corrector failed") as err:
        continuation(prob, ALG, ContinuationOptions(ds=0.1))
    assert len(err.value.branch.points) == len(br.points)
    # a start that Newton cannot converge in one iteration
    opts = ContinuationOptions(ds=0.1, newton_max_iter=1)
    bad = BifurcationProblem(fold_energy, [1.1, 0.0], 1.0, 0.0)
    with pytest.raises(ContinuationError, match="start did not converge"):
        continuation(bad, ALG, opts)
    failed = continuation(bad, ALG, opts, throw=False)
    assert failed.result is Result.CORRECTOR_FAILED and not failed.points
    with pytest.raises(ValueError):
        ContinuationOptions(ds=0.0)


# Soft folds: E = x^2/2 + (1 - cos y) + k y^2/2 - p y, with y marked soft by the hook (a stand-in for
# a loose knot's sliding: a washboard the path can turn back on without any branch end). On the
# branch x = 0, sin y + k y = p; folds where cos y = -k.
WASHBOARD_K = 0.1


def washboard_energy(u, p, args):
    x, y = u
    return x ** 2 / 2 + (1 - jnp.cos(y)) + WASHBOARD_K * y ** 2 / 2 - p * y


def y_is_soft(u, p, values, vectors):
    return values, vectors, np.abs(np.asarray(vectors)[1]) > 0.9


@pytest.mark.parametrize("soft_folds", ["slide", "follow"])
def test_soft_fold_is_no_branch_end_and_is_slid_across(soft_folds):
    from scipy.optimize import brentq

    prob = BifurcationProblem(washboard_energy, [0.0, 0.0], 0.0, None, soft_modes=y_is_soft)
    opts = ContinuationOptions(ds=0.05, ds_max=0.1, p_max=1.5, max_steps=120, soft_folds=soft_folds)
    br = continuation(prob, ALG, opts)
    y_fold = np.arccos(-WASHBOARD_K)
    p_fold = np.sin(y_fold) + WASHBOARD_K * y_fold
    soft = br.events_of("soft_fold")
    assert not br.events_of("fold") and not br.events_of("branch_point")
    assert len(soft) >= 1
    check_located(soft[0], "soft_fold", p_fold, [0.0, y_fold])
    assert (soft[0].morse_before, soft[0].morse_after) == (0, 0)
    if soft_folds == "follow":  # the path turns back in p on the unstable side of the washboard
        assert not br.slides
        i = soft[0].step
        assert br.points[i].p < p_fold and br.points[i].u[1] > y_fold
        return
    # slid: relaxed at p_fold + slide_dp into the next well of the washboard, then on to p_max
    (slide,) = br.slides
    p1 = p_fold + opts.resolved_arclength().slide_dp  # the default
    y_next = brentq(lambda y: np.sin(y) + WASHBOARD_K * y - p1, 2 * np.pi, 2.5 * np.pi)
    assert abs(slide.p - p1) <= 1e-14 and abs(slide.u[1] - y_next) <= 1e-10 and abs(slide.u[0]) <= 1e-12
    assert slide.energy_drop > 0 and abs(slide.distance - (y_next - y_fold)) <= 1e-8
    after = br.points[slide.step:]
    assert after[0].p == pytest.approx(p1, abs=1e-12) and all(q.morse_index == 0 for q in after)
    assert np.all(np.diff([q.p for q in after]) > 0) and br.result is Result.BOUNDARY
    # every point is an equilibrium of the washboard branch
    assert all(abs(np.sin(q.u[1]) + WASHBOARD_K * q.u[1] - q.p) <= 1e-10 for q in br.points)


# Two pitchforks 1e-4 apart on the trivial branch u = 0 of E = (1 - p) x^2/2 + (1 + 1e-4 - p) y^2/2 +
# (x^4 + y^4)/4: one step of 0.1 crosses both (Morse 0 -> 2).
def near_pair_energy(u, p, args):
    x, y = u
    return 0.5 * (1 - p) * x ** 2 + 0.5 * (1 + 1e-4 - p) * y ** 2 + 0.25 * (x ** 4 + y ** 4)


def test_spectrum_watching_step_control_separates_nearly_coincident_branch_points():
    prob = BifurcationProblem(near_pair_energy, [0.0, 0.0], 0.45)
    coarse = continuation(prob, ALG, ContinuationOptions(ds=0.1, ds_max=0.1, p_max=1.5))
    assert any(abs(b.morse_index - a.morse_index) == 2 for a, b in zip(coarse.points, coarse.points[1:]))
    fine = continuation(prob, ALG, ContinuationOptions(ds=0.1, ds_max=0.1, p_max=1.5, resolve_crossings=1e-6))
    # no step crosses more than one eigenvalue, and each crossing is a simple branch point, located
    assert all(abs(b.morse_index - a.morse_index) <= 1 for a, b in zip(fine.points, fine.points[1:]))
    e0, e1 = fine.events
    check_located(e0, "branch_point", 1.0, [0.0, 0.0])
    check_located(e1, "branch_point", 1.0 + 1e-4, [0.0, 0.0])
    assert (e0.multiplicity, e0.morse_before, e0.morse_after, e1.morse_before, e1.morse_after) == (1, 0, 1, 1, 2)


def test_an_unlocated_event_says_why():
    # Newton converged (residual and eigenvalue below event_tol) but along a soft mode, with the
    # Morse index changed: the message must not claim the values exceed event_tol (it did, on the
    # trefoil at N = 61: "residual 3.12e-14, critical eigenvalue 1.07e-14 > event_tol = 1e-10")
    from jaxrod.continuation.arclength.continuation import why_not_located
    from jaxrod.continuation.arclength.results import Event

    def event(residual, eigenvalue):
        return Event("fold", 20.7419, np.zeros(2), np.ones((2, 1)), np.array([eigenvalue]), residual, 4, 1, 1, 2, 7,
                     np.ones(3), False)

    soft = why_not_located(event(3.1e-14, 1.1e-14), 1e-10)
    assert "sliding mode's singular point" in soft and "Morse 1 -> 2" in soft and "> event_tol" not in soft
    assert why_not_located(event(1e-6, 1e-14), 1e-10).endswith("> event_tol = 1e-10")


@pytest.mark.parametrize("n_zero", [0, 3])
def test_the_dense_backends_lowest_pairs_equal_the_full_decomposition(n_zero):
    # DenseBackend.spectrum takes only the lowest eigenpairs from PARTIAL_MIN_SIZE on; the Morse
    # index (with an eigenvalue just inside and one just outside the band -rtol ||J||_2) and the
    # gauge modes' removal must be those of the full decomposition
    from jaxrod.linalg.bordered import PARTIAL_MIN_SIZE, DenseBackend, lowest_pairs_spectrum

    n, rtol = PARTIAL_MIN_SIZE + 40, 1e-6
    rng = np.random.default_rng(3)
    lam = np.concatenate([[-2.0, -0.5, -0.9e-6 * 7.0, -1.1e-6 * 7.0], [0.0] * n_zero,
                          np.linspace(0.01, 7.0, n - 4 - n_zero)])  # ||J||_2 = 7
    q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    J = (q * lam) @ q.T
    J = 0.5 * (J + J.T)
    vals, vecs, morse = DenseBackend().spectrum(J, 6, n_zero, rtol)
    full = np.linalg.eigvalsh(J)
    full = np.sort(full[np.sort(np.argsort(np.abs(full))[n_zero:])])
    assert lowest_pairs_spectrum(J, 6, n_zero, rtol) is not None  # the partial path was taken
    assert morse == int(np.sum(full < -rtol * np.max(np.abs(full)))) == 3
    np.testing.assert_allclose(vals, full[:6], rtol=0, atol=1e-12)
    np.testing.assert_allclose(J @ vecs, vecs * vals, rtol=0, atol=1e-10)
    # a J unstable beyond the lowest pairs falls back to the full decomposition
    assert lowest_pairs_spectrum(-np.abs(J) - 10.0 * np.eye(n), 6, 0, rtol) is None


# 9. Restabilisation: E = x^4/4 - x^2/2 - p x + y^2/2, the S-curve p = x^3 - x. From the stable branch
# x < -1/sqrt(3), p growing: a fold at x = -1/sqrt(3) (Morse 0 -> 1), the unstable middle branch back
# down in p, a fold at x = +1/sqrt(3), p = -2/(3 sqrt(3)) (1 -> 0), where the branch becomes stable again.
def s_curve_energy(u, p, args):
    x, y = u
    return x ** 4 / 4 - x ** 2 / 2 - p * x + y ** 2 / 2


def test_an_unstable_branch_is_followed_until_it_restabilises():
    from jaxrod.continuation.arclength import until_stable

    x0 = -1.2
    prob = BifurcationProblem(s_curve_energy, [x0, 0.0], x0 ** 3 - x0)
    opts = ContinuationOptions(ds=0.1, ds_max=0.2, max_steps=5, k=1, p_min=-3.0, p_max=3.0)
    br, back = until_stable(prob, ALG, opts, max_points=200, keep=3)
    r = 1 / np.sqrt(3)
    lost, = [e for e in br.events if e.morse_after > e.morse_before]
    check_located(lost, "fold", 2 * r / 3, [-r, 0.0])
    check_located(back, "fold", -2 * r / 3, [r, 0.0])
    assert (back.morse_before, back.morse_after) == (1, 0) and br.result is Result.STOPPED
    assert "restabilised" in br.message
    # chunks of 5 steps: the path is continuous, three points kept past the restabilisation
    assert len(br.points) == back.step + 3 and all(q.morse_index == 0 and q.u[0] > r for q in br.points[-3:])
    s = np.array([q.arclength for q in br.points])
    assert np.all(np.diff(s) > 0) and np.max(np.abs(br.u[:, 0] ** 3 - br.u[:, 0] - br.p)) <= 1e-10
    # not restabilised within max_points: stopped, saying so
    br, back = until_stable(prob, ALG, opts, max_points=8)
    assert back is None and br.result is Result.STOPPED and "not restabilised" in br.message


def test_the_branch_met_where_an_unstable_branch_restabilises():
    # System 2's branch y = 1, x^2 = p - 1 (Morse 1) restabilises at p = 2, where it crosses the
    # branch x^2 = y, p = y + y^2 (a transcritical point at x = y = 1). switch_branches from the
    # restabilising event gives that branch: stable (Morse 0) towards p < 2, unstable beyond.
    from jaxrod.continuation.arclength import switch_branches, until_stable

    p0 = 1.2
    prob = BifurcationProblem(pitchfork_energy, [np.sqrt(p0 - 1.0), 1.0], p0)
    opts = ContinuationOptions(ds=0.1, ds_max=0.2, max_steps=5, k=2, p_min=-3.0, p_max=4.0)
    _, back = until_stable(prob, ALG, opts, max_points=200, keep=3)
    check_located(back, "branch_point", 2.0, [1.0, 1.0])
    assert (back.morse_before, back.morse_after) == (1, 0)
    halves = switch_branches(prob, back, ALG, ContinuationOptions(ds=0.05, ds_max=0.1, max_steps=10, k=2,
                                                                  p_min=-3.0, p_max=4.0))
    by_side = {}
    for br in halves:
        x, y = br.u.T
        assert np.max(np.abs(x ** 2 - y)) <= 1e-9 and np.max(np.abs(br.p - y - y ** 2)) <= 1e-9  # the met branch
        by_side["below" if np.all(br.p < 2.0) else "above"] = sorted({int(m) for m in br.morse_index})
    assert by_side == {"below": [0], "above": [1]}


# 10. A small S: E = x^4/4 - eps x^2/2 - p x + y^2/2, p = x^3 - eps x, folds at x = -+sqrt(eps/3),
# 0.2 apart for eps = 0.03. A point just past the first fold (x = -0.09) and a step across the
# second (to x ~ +0.11): Newton from the nearer end (x = -0.09) converges to the first fold, which
# lies outside the step. It must not be reported again (the trefoil at N = 61 gave the same fold at
# 6.2160202871 pi twice, steps 55 and 56): the fold in the step is the second one.
def small_s_energy(u, p, eps):
    x, y = u
    return x ** 4 / 4 - eps * x ** 2 / 2 - p * x + y ** 2 / 2


def test_a_fold_outside_the_step_is_not_reported_again():
    eps = 0.03
    r = np.sqrt(eps / 3)
    x0 = -0.09
    p0 = x0 ** 3 - eps * x0
    prob = BifurcationProblem(small_s_energy, [x0, 0.0], p0, eps)
    t = np.array([1.0, 0.0, 3 * x0 ** 2 - eps])  # along the curve, x growing
    opts = ContinuationOptions(ds=0.2, ds_max=0.2, max_steps=1, k=1, p_min=-1.0, p_max=1.0)
    br = continuation(prob, ALG, opts, start=([x0, 0.0], p0, t), throw=False)
    assert br.points[0].u[0] > -r and br.points[1].u[0] > r  # the step crosses the second fold only
    (e,) = br.events
    check_located(e, "fold", -2 * eps / 3 * r, [r, 0.0])
    assert (e.morse_before, e.morse_after) == (1, 0)


# 11. Two branch points close together on a trivial branch: E = x^4/4 + p (p - 0.1) x^2/2 + y^2/2,
# lambda = p (p - 0.1) crosses zero at p = 0 (Morse 0 -> 1) and p = 0.1 (1 -> 0). Steps of 0.13 from
# p = -0.11: the first (to 0.02) holds the crossing at 0, the second (to 0.15) the one at 0.1. From
# the second step's nearer end (|lambda| smaller at 0.02) the unfolded system converges to the
# first crossing again: the second step's event must be the branch point at 0.1 (the trefoil at
# N = 61 reported its 2 -> 1 crossing near 6.2332 pi as not located, Newton having found the 1 -> 2
# one at 6.3152 pi, and the hyperplane corrector failing next to the root).
def two_crossings_energy(u, p, args):
    x, y = u
    return x ** 4 / 4 + p * (p - 0.1) * x ** 2 / 2 + y ** 2 / 2


def test_a_branch_point_already_located_is_not_taken_for_the_next():
    prob = BifurcationProblem(two_crossings_energy, [0.0, 0.0], -0.11)
    opts = ContinuationOptions(ds=0.13, ds_max=0.13, max_steps=2, k=2, p_min=-1.0, p_max=1.0)
    br = continuation(prob, ALG, opts, throw=False)
    assert [q.morse_index for q in br.points] == [0, 1, 0] and br.points[2].p > 0.1
    first, second = br.events
    check_located(first, "branch_point", 0.0, [0.0, 0.0])
    check_located(second, "branch_point", 0.1, [0.0, 0.0])
    assert (first.morse_before, first.morse_after, second.morse_before, second.morse_after) == (0, 1, 1, 0)


def coupled_energy(u, p, mu):
    # a 4-DOF energy with every third derivative nonzero and a p-dependent Hessian
    x = u
    return (jnp.sum(x ** 4) / 4 + mu * x[0] * x[1] * x[2] - p * jnp.dot(x, x) / 2 + jnp.sin(p * x[3]) * x[0] ** 2
            + x[1] ** 2 * x[3] + jnp.exp(0.1 * p * x[2]))


def test_the_test_functions_adjoint_equals_reverse_mode_through_the_bordered_solve():
    """``singular_tests`` (the branch-point locator's Newton matrix) and ``wjw_gradient`` (the fold
    locator's) come from a jitted linearisation, the backend's bordered solves and two contracted
    third-derivative gradients: they equal reverse-mode differentiation of the traceable
    ``traced_singular_tests`` (through the bordered solve) and of w^T J w, to roundoff."""
    import jax

    prob = BifurcationProblem(coupled_energy, [0.3, -0.7, 0.5, 1.1], 0.4, 0.8)
    u, p, b = jnp.array([0.3, -0.7, 0.5, 1.1]), jnp.asarray(0.4), np.array([0.5, 0.1, -0.3, 0.8])
    (gu, gp), (st, F, J, Fp, w) = prob.singular_tests(u, p, prob.args, b)
    # the references jitted: eagerly each operation compiles on its own (8.5 s; 1.5 s jitted)
    ref_u, ref_p = jax.jit(jax.jacrev(lambda x, q: prob.traced_singular_tests(x, q, prob.args, b)[0], argnums=(0, 1)))(u, p)
    ref_st = jax.jit(lambda x, q: prob.traced_singular_tests(x, q, prob.args, b)[0])(u, p)
    np.testing.assert_allclose(st, ref_st, rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(gu, ref_u, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(gp, ref_p, rtol=1e-11, atol=1e-12)
    assert np.max(np.abs(ref_u)) > 0.1 and abs(ref_p[1]) > 1e-3  # the check is not of zeros
    hess = jax.hessian(coupled_energy)
    wu, wp = prob.wjw_gradient(u, p, prob.args, jnp.asarray(w))
    ref = jax.jit(jax.grad(lambda x, q: w @ hess(x, q, 0.8) @ w, argnums=(0, 1)))(u, p)
    np.testing.assert_allclose(wu, ref[0], rtol=1e-12, atol=1e-13)
    assert float(wp) == pytest.approx(float(ref[1]), rel=1e-12, abs=1e-13)


def test_a_morse_change_one_step_after_a_turn_is_that_folds_crossing():
    """A fold located with the Morse index unchanged across its step, and the index changing in the
    next step without a turn: the fold's crossing counted one step late (the soft split lags the
    turn where the fold's mode mixes with a slide; the trefoil's tightening side at N = 121), so the
    fold is reported again with the new index and no branch point is sought. Further away, or a
    change by two, goes to the branch-point locator as before."""
    from jaxrod.continuation.arclength.events import find_events
    from jaxrod.continuation.arclength.results import Event, Point

    def point(p, tp, morse):
        return Point(np.zeros(2), p, np.array([0.0, 0.0, tp]), np.zeros(2), np.eye(2), morse, 1, 0.1, 0.0)

    fold = Event("fold", -1.0, np.zeros(2), np.eye(2)[:, :1], np.zeros(1), 1e-14, 3, 1, 0, 0, 4,
                 np.array([0.0, 0.0, 1.0]), True)
    a, b = point(-0.99, 0.3, 0), point(-0.95, 0.5, 1)
    (e,) = find_events(None, None, a, b, 5, [fold])
    assert e.kind == "fold" and e.p == fold.p and (e.morse_before, e.morse_after, e.step) == (0, 1, 5)

    class Refused(Exception):
        pass

    def no_locator(*args, **kwargs):
        raise Refused

    import jaxrod.continuation.arclength.events as events

    saved = events.locate_branch_points
    events.locate_branch_points = no_locator
    try:
        for known, b2 in (([fold], point(-0.95, 0.5, 2)),  # the index changed by two
                          ([Event(**{**fold.__dict__, "step": 3})], b),  # the fold two steps back
                          ([Event(**{**fold.__dict__, "morse_after": 1})], b)):  # the fold changed the index itself
            with pytest.raises(Refused):
                find_events(None, None, a, b2, 5, known)
    finally:
        events.locate_branch_points = saved


# A pitchfork whose critical mode mixes with a near-null soft mode of the same parity (a loose
# knot's slide next to a symmetry-breaking mode on its symmetric branch): E = s a^2/2 + c a b +
# (1 - p) b^2/2 + (a^4 + b^4)/4, with a marked soft by the hook wherever a direction of the span is
# (almost) pure a. On the trivial branch J = [[s, c], [c, 1 - p]] is singular at p* = 1 - c^2/s, with
# the null vector (-c, s) / |.|, 98% a and 2% b for c = 7 s: no clean slide, so the event. There the
# slide's Rayleigh quotient (s) is nearer zero than the complement's Ritz value (1 - p* = c^2/s), the
# rule that refused it before (the trefoil at N = 128, D/L = 0.010, opening side).
MIXED_S, MIXED_C = 1e-7, 7e-7


def mixed_slide_energy(u, p, args):
    a, b = u
    return 0.5 * MIXED_S * a ** 2 + MIXED_C * a * b + 0.5 * (1 - p) * b ** 2 + 0.25 * (a ** 4 + b ** 4)


def a_is_soft(u, p, values, vectors, threshold=5e-3):
    """Split the direction of the span nearest to pure a off as soft (its fraction of b below
    threshold), the rest as Ritz pairs, as ``jaxrod.linalg.stability.split_slide`` does for a slide."""
    lam, V = np.asarray(values, dtype=float), np.asarray(vectors, dtype=float)
    along = V[0]
    if 1.0 - float(along @ along) >= threshold:
        return lam, V, np.zeros(lam.size, dtype=bool)
    c = along / np.linalg.norm(along)
    rest = np.linalg.svd(np.eye(lam.size) - np.outer(c, c))[0][:, :lam.size - 1]
    ritz, w = np.linalg.eigh(rest.T @ np.diag(lam) @ rest)
    values = np.concatenate([[c @ (lam * c)], ritz])
    coef = np.concatenate([c[:, None], rest @ w], axis=1)
    order = np.argsort(values)
    return values[order], V @ coef[:, order], (np.arange(lam.size) == 0)[order]


def test_a_branch_point_whose_null_vector_mixes_with_a_soft_mode_is_located_where_J_is_singular():
    prob = BifurcationProblem(mixed_slide_energy, [0.0, 0.0], 0.93, None, soft_modes=a_is_soft)
    br = continuation(prob, ALG, ContinuationOptions(ds=0.05, ds_max=0.05, p_max=1.1, max_steps=10))
    (bp,) = br.events_of("branch_point")
    check_located(bp, "branch_point", 1.0 - MIXED_C ** 2 / MIXED_S, [0.0, 0.0])
    assert (bp.morse_before, bp.morse_after) == (0, 1)
    v = np.asarray(bp.v[:, 0]) / np.linalg.norm(bp.v[:, 0])
    assert abs(abs(v[1]) - MIXED_S / np.hypot(MIXED_S, MIXED_C)) <= 1e-6  # the mixed null vector itself
