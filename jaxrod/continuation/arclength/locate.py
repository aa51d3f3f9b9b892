"""Exact location of folds and branch points.

Fold: Newton on the minimally augmented system (Govaerts) G(u, p) = (F, sigma) = 0, where sigma
comes from the bordered solve [[J, b], [b^T, 0]] [w; sigma] = [0; 1]: sigma = 0 exactly when J is
singular (b not orthogonal to its kernel; sigma ~ -lambda_min when b ~ v). Differentiating the
bordered system and using the adjoint vector, which for symmetric J is w itself, gives
dsigma = -w^T dJ w: sigma_u = -E'''[w, w, .], sigma_p = -w^T J_p w, one reverse pass over the
Hessian-vector product (``problem.wjw_gradient``, exact). The Newton matrix [[J, F_p], [sigma_u^T,
sigma_p]] is again an (n+1) bordered matrix, regular at a quadratic fold (F_p not in range(J),
E'''[v, v, v] != 0), so Newton converges quadratically; b is refreshed with w each iteration (the
root does not depend on b). Moore-Spence (F = 0, J v = 0, <v, v0> = 1 in (u, v, p)) has the same
root and regularity but 2n+1 unknowns; the minimally augmented form needs only bordered solves with
J, which a block-tridiagonal backend provides. A p-turn with |v^T F_p| < 1e-3 |F_p| (F_p in
range(J): the fold system is singular there and converges only linearly) is retried as a branch
point with the unfolded system below, and reported as one if that converges with beta = 0.

Branch point: there F_p is in range(J), [J, F_p] has rank n-1 and two branches cross, so every
system containing F(u, p) = 0 with unknowns (u, p) -- Moore-Spence, the fold system above, the
bordered determinant -- is singular at the point. A regular system needs an unfolding parameter
beta (Moore 1980): for a simple branch point, Newton on
    F(u, p) + beta v0 = 0,  sigma(u, p) = 0,  tau = w^T F_p = 0      in (u, p, beta)
(n+2 equations; beta = 0 at the solution), which is regular when the two branches cross
transversally (transcritical, or a Z2 pitchfork), with a doubly bordered Newton matrix
[[J, (F_p, v0)], [(sigma_u, tau_u)^T, ...]] whose derivative rows come from reverse mode through the
bordered solve (``problem.singular_tests``). It starts from the bracket end with the smaller
crossing eigenvalue. Fallback, and the method for k > 1 eigenvalues crossing at once (symmetric
double branch points, where the unfolded system would need 2x2 singularity blocks): the followed
branch is a smooth curve through the point, parametrised by s = <z - z_a, t_a>, and each crossing
eigenvalue lambda(s) has a simple root, found by Brent's method on [0, s_b] (bracketed,
superlinear), each evaluation a corrector run on the hyperplane <z - z_a, t_a> = s plus an
eigensolve. That corrector is itself singular at the point unless its iterates stay in a symmetric
subspace (true on a symmetric trivial branch; not near a transcritical crossing, where the unfolded
system is needed). Roots that coincide (to 1e-9 of the bracket, or to within the eigenvalues' noise:
all below event_tol at the roots' mean) make one event of multiplicity k, split roots (a broken
symmetry) separate events.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.optimize import brentq

from .corrector import correct
from ..kinds import EventKind
from .results import Event, Point


# Newton iterations within which the fold system, started at a bracket end, converges to roundoff
# at a quadratic fold (measured: 3 on the trefoil, N = 121, from 2e-5 pi away)
FOLD_QUADRATIC_ITERATIONS = 6


def _done(res, prev, tol):
    # one Newton step more once below tol: quadratic convergence takes the root to roundoff,
    # so the located p does not depend on where the iteration started
    return res <= tol and (prev <= tol or res <= 1e-3 * tol)


def locate_fold(problem, opts, starts, morse, step):
    """Fold near the Points ``starts`` (the bracket's ends, the preferred first; Newton on
    (F, sigma)); morse = (before, after). -> Event: "fold", "soft_fold" (a turn along a soft mode,
    Morse index unchanged), "soft_turn" (a turn along soft directions with nothing to locate), or
    "branch_point" (a p-turn with F_p orthogonal to the kernel)."""
    if isinstance(starts, Point):
        starts = (starts,)
    ends = sorted(starts, key=lambda q: q.arclength)  # in path order
    found, start, elsewhere = None, starts[0], False
    for start in starts:
        found = _fold_from(problem, opts, start, morse)
        if found is not None and found.ok and not _turn_in_step(found.p, ends):
            # converged to a turn of p outside this step: two folds close together (a small S) with a
            # point between them, and Newton from it found the previous step's fold again
            found, elsewhere = None, True
            continue
        # a soft critical mode where the Morse index changed: Newton found the slide's singular
        # point next to the shape fold (the two nearly coincide); try from the other end
        if found is not None and not (found.ok and found.soft and morse[0] != morse[1]):
            break
    same_morse = morse[0] == morse[1]
    if (found is None or not found.ok) and not same_morse and len(ends) == 2 and (problem.soft_modes is not None
                                                                                   or elsewhere):
        # Newton diverged or stalled from both ends (the critical mode mixed with a near-null slide:
        # the trefoil at N = 128, D/L = 0.031), or found only a turn outside the step: the shape
        # fold by its own eigenvalue's root along the bracket
        found = _fold_by_bracket(problem, opts, ends[0], ends[1], morse) or found
    if (found is None or not found.ok) and same_morse and len(ends) == 2 and problem.soft_modes is not None:
        # not located from either end: a turn along a soft mode that Newton did not converge to?
        found = _fold_by_bracket(problem, opts, ends[0], ends[1], morse, along_soft=True) or found
    if (found is None or not found.ok) and same_morse and _turns_along_soft(ends):
        # No eigenvalue vanishes: the path, running along a soft direction (its tangent over 90%
        # there, measured on the trefoil next to the slides), turned in p without a singular
        # point to locate. Reported as a "soft_turn", crossed like a soft fold.
        q = ends[0]
        j = int(np.argmax(q.soft))
        return Event(EventKind.SOFT_TURN, q.p, q.u, q.eigenvectors[:, [j]], q.eigenvalues[[j]], float("nan"), 0, 1,
                     morse[0], morse[1], step, np.asarray(q.tangent), True)
    width = abs(ends[-1].p - ends[0].p)
    if found is None or (not found.ok and not abs(found.p - starts[0].p) <= 10 * width + 1e-12):
        # diverged, or stopped far outside the bracket: reported at the bracket's end, not located
        q = starts[0]
        j0 = int(np.argmin(np.abs(q.eigenvalues)))
        return Event(EventKind.FOLD, q.p, q.u, q.eigenvectors[:, [j0]], q.eigenvalues[[j0]], np.inf, opts.locate_max_iter, 1,
                     morse[0], morse[1], step, np.asarray(q.tangent), False)
    tangent = np.asarray(start.tangent)
    if found.ok and found.soft:
        if same_morse:
            # the path turned back along a soft mode (a loose knot's strands sliding: a saddle-node
            # of the discretisation's tiny sliding landscape): no branch end
            return found.event(EventKind.SOFT_FOLD, morse, step, tangent)
        # the Morse index changed, so a shape fold lies in this bracket too: find it by its own
        # eigenvalue along the bracket; unresolved, it is reported as not located
        shape = len(ends) == 2 and _fold_by_bracket(problem, opts, ends[0], ends[1], morse)
        if not shape:
            return found._replace(ok=False).event(EventKind.FOLD, morse, step, tangent)
        found = shape
    fold = found.event(EventKind.FOLD, morse, step, tangent)
    # p turning back with F_p orthogonal to the kernel is no fold but a branch point (a pitchfork
    # seen from its non-symmetric branch), where (F, sigma) is singular; the unfolded system is not.
    # A fold: (F, sigma) is regular there, so Newton converged quadratically (few iterations),
    # or F_p is clearly transversal to the kernel. At a branch point the system is singular and
    # Newton crawls (linear convergence: many iterations), and v^T F_p -> 0.
    v, Fp = found.vectors[:, found.k], np.asarray(found.Fp)
    if found.ok and (found.iterations <= FOLD_QUADRATIC_ITERATIONS or abs(v @ Fp) > 1e-3 * np.linalg.norm(Fp)):
        return fold
    bp = simple_branch_point(problem, opts, found.u, found.p, v, morse, step, tangent)
    return fold if bp is None else bp


def _turn_in_step(p, ends):
    """Whether p can be the turning point of the path between the Points ends (path order): where
    p rises and then falls along the step, the turn is a maximum, at least the larger end's p;
    where it falls and then rises, a minimum. (A single Point: no bracket to check.)"""
    if len(ends) != 2:
        return True
    a, b = ends
    slack = 1e-12 * max(1.0, abs(a.p), abs(b.p))
    if a.tangent[-1] > 0.0:
        return p >= max(a.p, b.p) - slack
    return p <= min(a.p, b.p) + slack


class _FoldTry(NamedTuple):
    """A run of the fold system: the last iterate (u, p), J and F_p there, its residual and
    iterations; the spectrum of J there (values, vectors), k the eigenvalue nearest zero; ok:
    residual and that eigenvalue within event_tol; soft: ok, and the critical mode is soft."""

    u: np.ndarray
    p: float
    J: object
    Fp: object
    residual: float
    iterations: int
    values: np.ndarray
    vectors: np.ndarray
    k: int
    ok: bool
    soft: bool

    def event(self, kind, morse, step, tangent):
        k = self.k
        return Event(kind, self.p, self.u, self.vectors[:, [k]], self.values[[k]], self.residual, self.iterations, 1,
                     morse[0], morse[1], step, tangent, self.ok)


def _classified(problem, opts, morse, u, p, J, Fp, res, it):
    """The _FoldTry of a fold-system run that ended at (u, p), or None if it diverged."""
    if not np.isfinite(res):
        return None
    vals, vecs, _ = problem.backend.spectrum(J, opts.k + max(morse), problem.n_zero_modes, opts.eig_rtol)
    k = int(np.argmin(np.abs(vals)))
    ok = bool(res <= opts.event_tol and abs(vals[k]) <= opts.event_tol)
    soft = ok and _critical_mode_is_soft(problem, u, p, vals, vecs)
    return _FoldTry(u, p, J, Fp, res, it, vals, vecs, k, ok, soft)


def _fold_from(problem, opts, start, morse):
    """Newton on the fold system from one Point, the border first the smallest shape mode's
    eigenvector (a shape fold next to a near-null slide), then, if that diverges or stalls (the
    border orthogonal to the kernel: a fold along the slide), the smallest mode's of all.
    -> _FoldTry, or None if it diverged."""
    lam = np.abs(start.eigenvalues)
    order = [int(np.argmin(lam))]
    if start.soft is not None and start.soft.any() and not start.soft.all():
        order.insert(0, int(np.argmin(np.where(start.soft, np.inf, lam))))
    for j0 in dict.fromkeys(order):
        u, p, J, Fp, res, it = _fold_newton(problem, opts, start.u, start.p, start.eigenvectors[:, j0])
        if np.isfinite(res) and res <= opts.event_tol:
            break
    return _classified(problem, opts, morse, u, p, J, Fp, res, it)


def _turns_along_soft(ends, share=0.9):
    """Whether the u-part of the tangent at each end lies mostly (> share) in the soft directions."""
    for q in ends:
        if q.soft is None or not q.soft.any():
            return False
        t = np.asarray(q.tangent[:-1]) / max(np.linalg.norm(q.tangent[:-1]), 1e-300)
        if np.linalg.norm(q.eigenvectors[:, q.soft].T @ t) <= share:
            return False
    return True


def _critical_mode_is_soft(problem, u, p, vals, vecs):
    """Whether the eigen-direction nearest zero at a located fold is a soft one (the problem's
    ``soft_modes`` hook on the span of the lowest eigenpairs): the soft direction's Rayleigh
    quotient is nearer zero than every other Ritz value there."""
    if problem.soft_modes is None:
        return False
    values, _, soft = (np.asarray(a) for a in problem.soft_modes(u, p, vals, vecs))
    soft = soft.astype(bool)
    if not soft.any() or soft.all():
        return False
    return bool(np.min(np.abs(values[soft])) < np.min(np.abs(values[~soft])))


def _null_vector_is_slide(problem, u, p, value, vector):
    """Whether the null vector ``vector`` (n, 1) of J at a located singular point is itself a clean
    slide (the problem's ``soft_modes`` hook on that one vector: its sliding fraction below the
    problem's threshold), i.e. the point is a slide's singular point, not a change of shape.

    Why not ``_critical_mode_is_soft`` (the slide's Rayleigh quotient against the complement's Ritz
    values): where a symmetry-breaking mode crosses zero next to a near-null slide of the same parity,
    the two mix, and at the point where J is singular the split leaves both the slide's Rayleigh
    quotient and the complement's lowest Ritz value positive (the trefoil at N = 128, D/L = 0.010,
    opening side, on the two-fold symmetric branch: 7.2e-8 and 5.3e-7, J's null vector sliding
    fraction 0.020). The point is still the branch's only singular point in the bracket where the
    Morse index changes (Haynsworth: with the slide's quotient s > 0, J is singular exactly where the
    Schur complement of the slide is), so it is the event; refusing it left the root of the Ritz
    value, 4.3e-6 pi away, where J is not singular (critical eigenvalue 5.8e-9)."""
    if problem.soft_modes is None:
        return False
    _, _, soft = problem.soft_modes(u, p, np.asarray(value), np.asarray(vector))
    return bool(np.asarray(soft, dtype=bool)[0])


def _shape_spectrum(problem, opts, J, u, p, m):
    """The m lowest eigenpairs (values (m,), vectors (n, m)) of J with the soft directions (the
    problem's ``soft_modes`` hook) split off: the Ritz pairs of the rest of the span, ascending;
    and the soft directions' (values (j,), vectors (n, j)), j = 0 without the hook.
    -> (values, vectors, soft_values, soft_vectors)."""
    if problem.soft_modes is None:
        vals, vecs, _ = problem.backend.spectrum(J, m, problem.n_zero_modes, opts.eig_rtol)
        return vals, vecs, vals[:0], vecs[:, :0]
    vals, vecs, _ = problem.backend.spectrum(J, m + 2, problem.n_zero_modes, opts.eig_rtol)
    values, vectors, soft = (np.asarray(a) for a in problem.soft_modes(u, p, vals, vecs))
    keep = ~soft.astype(bool)
    return values[keep][:m], vectors[:, keep][:, :m], values[~keep], vectors[:, ~keep]


def _on_bracket(problem, opts, a, b, m):
    """at(s) -> (Correction, (values, vectors)): the branch between Points a and b corrected on the
    hyperplane <z - z_a, t_a> = s (0 <= s <= s_b), with its m lowest shape eigenpairs (soft
    directions split off); and s_b. A smooth parametrisation through branch points and folds alike,
    as long as the branch turns by less than 90 degrees between a and b. Raises _Failed."""
    be, args = problem.backend, problem.args
    za, zb, ta = a.z, b.z, a.tangent
    sb = float((zb - za) @ ta)
    cache = {}

    def at(s):
        if s not in cache:
            # the chord z_a + (s/s_b)(z_b - z_a) lies on that hyperplane: a second-order predictor
            c = correct(be, lambda u, p: problem.linearise(u, p, args), za + (s / sb) * (zb - za), ta,
                        opts.newton_tol, opts.newton_max_iter)
            if not c.converged:
                raise _Failed
            cache[s] = (c, _shape_spectrum(problem, opts, c.lin[1], c.z[:-1], float(c.z[-1]), m))
        return cache[s]

    return at, sb


def _fold_by_bracket(problem, opts, a, b, morse, along_soft=False):
    """A fold that Newton from the bracket's ends missed, found by the root of its critical
    eigenvalue along the bracket (Brent, on the hyperplane parametrisation), then Newton on the
    fold system from there with that mode as the border. The critical eigenvalue is the lowest
    shape one (a shape fold next to a slide's singular point, where Newton landed), or, with
    along_soft, the soft direction's (a turn along the slide that Newton did not converge to).
    -> _FoldTry, or None if not found or not of that kind."""
    lo = min(morse)
    try:
        at, sb = _on_bracket(problem, opts, a, b, lo + 1)

        def f(s):
            values, _, soft_values, _ = at(s)[1]
            if along_soft and soft_values.size == 0:
                raise _Failed
            return soft_values[0] if along_soft else values[lo]

        if f(0.0) * f(sb) >= 0:
            return None
        s = brentq(f, 0.0, sb, xtol=1e-15 * abs(sb), rtol=1e-15, maxiter=100)
    except (_Failed, ValueError):
        return None
    c, (vals, vecs, _, soft_vecs) = at(s)
    border = soft_vecs[:, 0] if along_soft else vecs[:, lo]
    found = _classified(problem, opts, morse, *_fold_newton(problem, opts, c.z[:-1], float(c.z[-1]), border))
    if found is not None and found.ok and not _turn_in_step(found.p, (a, b)):
        found = None  # Newton left the bracket for another turn: the root below is this step's fold
    if (found is None or not found.ok) and not along_soft:
        # Newton on the fold system did not converge from the root either (a near-null slide next
        # to the critical mode): the root itself is the fold, a point of the branch (F = 0 to the
        # corrector's tolerance) where the shape eigenvalue vanishes (to Brent's tolerance); the
        # tangent's p-component vanishes there with it (p is stationary along the branch)
        ok = bool(c.residual <= opts.event_tol and abs(vals[lo]) <= opts.event_tol)
        return _FoldTry(c.z[:-1].copy(), float(c.z[-1]), c.lin[1], c.lin[2], float(c.residual), 0, vals, vecs, lo, ok,
                        False)
    if found is None or (found.ok and found.soft != along_soft):
        return None
    return found


def _fold_newton(problem, opts, u, p, b, args=None):
    """Newton on (F, sigma) from (u, p) with the border b (refreshed with w each iteration), at
    args (default problem.args). -> (u, p, J, F_p, residual, iterations)."""
    be, n = problem.backend, problem.n
    args = problem.args if args is None else args
    u, p = np.array(u), float(p)
    res = np.inf
    for it in range(opts.locate_max_iter + 1):
        F, J, Fp = problem.linearise(u, p, args)
        w, sigma = be.bordered_solve(J, b, b, 0.0, np.zeros(n), 1.0)
        gu, gp = problem.wjw_gradient(u, p, args, w)
        res, prev = float(np.sqrt(np.sum(np.asarray(F) ** 2) + float(sigma) ** 2)), res
        if not np.isfinite(res) or _done(res, prev, opts.newton_tol) or it == opts.locate_max_iter:
            break
        du, dp = be.bordered_solve(J, Fp, -np.asarray(gu), -float(gp), -np.asarray(F), -float(sigma))
        u, p = u + np.asarray(du), p + float(dp)
        b = np.asarray(w) / np.linalg.norm(w)
    return u, p, J, Fp, res, it


class _Failed(Exception):
    pass


def _norm(*parts):
    """Euclidean norm of the concatenated parts; inf (without a RuntimeWarning) when a diverging
    Newton iteration has overflowed them: the caller then gives up on that start."""
    with np.errstate(over="ignore", invalid="ignore"):
        return float(np.sqrt(sum(np.sum(np.asarray(a, dtype=float) ** 2) for a in parts)))


def simple_branch_point(problem, opts, u, p, v0, morse, step, tangent):
    """Newton on the unfolded system (F + beta v0, sigma, tau) = 0 from (u, p). -> Event, or None."""
    be, args = problem.backend, problem.args
    u, p, beta, bvec = np.array(u), float(p), 0.0, np.asarray(v0)
    res = np.inf
    for it in range(opts.locate_max_iter + 1):
        (gu, gp), (st, F, J, Fp, w) = problem.singular_tests(u, p, args, bvec)
        G = np.asarray(F) + beta * v0
        res, prev = _norm(G, st), res
        if not np.isfinite(res) or _done(res, prev, opts.newton_tol) or it == opts.locate_max_iter:
            break
        gp = np.asarray(gp)
        D = np.array([[gp[0], 0.0], [gp[1], 0.0]])
        du, dy = be.bordered_solve(J, np.stack([Fp, v0], axis=1), np.asarray(gu).T, D, -G, -np.asarray(st))
        u, p, beta = u + np.asarray(du), p + float(dy[0]), beta + float(dy[1])
        bvec = np.asarray(w) / np.linalg.norm(w)
    res = _norm(F, st)  # beta = 0 too
    if not np.isfinite(res) or res > opts.event_tol:
        return None
    vals, vecs, _ = be.spectrum(J, opts.k + max(morse), problem.n_zero_modes, opts.eig_rtol)
    k = int(np.argmin(np.abs(vals)))
    if abs(vals[k]) > opts.event_tol or _null_vector_is_slide(problem, u, p, vals[[k]], vecs[:, [k]]):
        return None  # not singular, or singular along a slide only (a soft fold, not a branch point)
    return Event(EventKind.BRANCH_POINT, p, u, vecs[:, [k]], vals[[k]], res, it, 1, morse[0], morse[1], step, tangent, True)


def _same_point(e, other):
    """Whether two located events are one point of the path (to far below any step)."""
    scale = max(1.0, abs(e.p))
    return bool(abs(e.p - other.p) <= 1e-9 * scale
                and np.linalg.norm(np.asarray(e.u) - np.asarray(other.u)) <= 1e-6 * (1.0 + np.linalg.norm(e.u)))


def _shape_index(point, rank):
    """Index, among a Point's computed eigenpairs, of its rank-th shape mode (soft modes skipped)."""
    if point.soft is None or not np.any(point.soft):
        return rank
    shape = np.flatnonzero(~np.asarray(point.soft, dtype=bool))
    return int(shape[min(rank, shape.size - 1)])


def locate_branch_points(problem, opts, a, b, step, known=()):
    """Branch point(s) between Points a and b (Morse index differs, no fold). -> [Event].
    known: events already located on this path; Newton landing on one of them has found an
    earlier crossing, not this step's."""
    lo, k = min(a.morse_index, b.morse_index), abs(a.morse_index - b.morse_index)
    # the crossing eigenvalues are counted among the shape modes (soft directions split off), as
    # the Morse index is: a slide's eigenvalue must not be taken for the crossing one
    at, sb = _on_bracket(problem, opts, a, b, lo + k)
    morse = (a.morse_index, b.morse_index)
    if k == 1:
        # the crossing mode by its rank among the shape modes (soft directions split off), as the
        # Morse index counts it: a soft mode's index must not be taken for it
        ends = [(q, _shape_index(q, lo)) for q in (a, b)]
        (start, j0), _ = sorted(ends, key=lambda e: abs(e[0].eigenvalues[e[1]]))
        e = _new_branch_point(problem, opts, start.u, start.p, start.eigenvectors[:, j0], morse, step, start.tangent,
                              known)
        if e is not None:
            return [e]
    roots, calls, tried = _crossing_roots(at, lo, k, sb)
    if roots is not None:
        return _grouped_events(opts, at, sb, roots, calls, lo, a, b, step)
    if k == 1 and tried:
        # The hyperplane corrector is singular at a branch point and may fail right next to it
        # (the trefoil at N = 61, 6.2332 pi: at s = 0.2540 of 0.5, after |lambda| = 2.9e-7 at
        # 0.2537): the unfolded system, regular there, from the nearest point Brent reached
        s_best = min(tried, key=lambda s: abs(tried[s][1]))
        c, (vals, vecs, _, _) = at(s_best)
        e = _new_branch_point(problem, opts, c.z[:-1], float(c.z[-1]), vecs[:, tried[s_best][0]], morse, step,
                              a.tangent if s_best < 0.5 * sb else b.tangent, known)
        if e is not None:
            return [e]
    return [Event(EventKind.BRANCH_POINT, a.p, a.u, a.eigenvectors[:, lo:lo + k], a.eigenvalues[lo:lo + k], np.inf,
                  calls, k, a.morse_index, b.morse_index, step, a.tangent, False)]


def _new_branch_point(problem, opts, u, p, v, morse, step, tangent, known):
    """simple_branch_point from (u, p) along v, unless it lands on an event already located
    (an earlier crossing of the same or another mode, Newton's basin reaching past this step).
    Not required to lie between the bracket's ends: the Morse index counts an eigenvalue negative
    only below a band, so a crossing may sit just outside the step where the count changes."""
    e = simple_branch_point(problem, opts, u, p, v, morse, step, tangent)
    if e is None or any(_same_point(e, other) for other in known):
        return None
    return e


def _crossing_roots(at, lo, k, sb):
    """The hyperplane coordinates s in (0, sb) where the shape eigenvalues lo .. lo + k - 1 cross
    zero (Brent on each). -> (roots, function calls, tried {s: (index, eigenvalue)}); roots is
    None where a corrector failed or an eigenvalue does not change sign over the bracket."""
    roots, calls, tried = [], 0, {}
    try:
        for j in range(lo, lo + k):
            def f(s, j=j):  # the shape eigenvalue j on the hyperplane s
                value = at(s)[1][0][j]
                tried[s] = (j, value)
                return value

            if f(0.0) * f(sb) >= 0:  # the tracked eigenvalue does not change sign over the bracket
                raise _Failed
            s, info = brentq(f, 0.0, sb, xtol=1e-15 * abs(sb), rtol=1e-15, maxiter=100, full_output=True)
            roots.append(s)
            calls += info.function_calls
    except _Failed:  # a corrector failure, or no sign change
        return None, calls, tried
    return roots, calls, tried


def _grouped_events(opts, at, sb, roots, calls, lo, a, b, step):
    """One Event per group of coincident roots (a symmetric, multiple crossing): equal to 1e-9 of
    the bracket, or split only by the noise on the eigenvalues (~ roundoff / |dlambda/ds|), i.e.
    every eigenvalue of the group is below event_tol at the mean of its roots. The second case is
    a symmetric crossing seen in a non-orthonormal gauge (a pinned rod), where the crossing pair
    is not degenerate away from the point, so its roots differ by that noise."""
    def coincident(g):
        rs = [roots[i] for i in g]
        if max(rs) - min(rs) <= 1e-9 * abs(sb):
            return True
        try:
            vals = at(float(np.mean(rs)))[1][0]
        except _Failed:
            return False
        return bool(np.max(np.abs(vals[[lo + i for i in g]])) <= opts.event_tol)

    sign = 1 if b.morse_index > a.morse_index else -1
    groups, events, before = [], [], a.morse_index
    for i in np.argsort(roots):
        if groups and coincident(groups[-1] + [i]):
            groups[-1].append(i)
        else:
            groups.append([i])
    for g in groups:
        s = float(np.mean([roots[i] for i in g]))
        c, (vals, vecs, _, _) = at(s)
        idx = [lo + i for i in g]
        crit = vals[idx]
        ok = bool(c.residual <= opts.event_tol and np.max(np.abs(crit)) <= opts.event_tol)
        events.append(Event(EventKind.BRANCH_POINT, float(c.z[-1]), c.z[:-1], vecs[:, idx], crit, c.residual, calls,
                            len(g), before, before + sign * len(g), step, a.tangent if s < 0.5 * sb else b.tangent, ok))
        before += sign * len(g)
    return events
