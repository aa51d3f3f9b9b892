"""Exact location of folds and branch points.

Fold: Newton on the minimally augmented system (Govaerts) G(u, p) = (F, sigma) = 0, sigma from
[[J, b], [b^T, 0]] [w; sigma] = [0; 1] (zero iff J is singular; dsigma = -w^T dJ w), regular at a
quadratic fold. A p-turn with F_p nearly orthogonal to the kernel is retried as a branch point.

Branch point: every system containing F(u, p) = 0 in (u, p) is singular there, so Newton runs on
the unfolded system (Moore 1980)
    F(u, p) + beta v0 = 0,  sigma(u, p) = 0,  tau = w^T F_p = 0      in (u, p, beta),
regular at a transversal crossing. Fallback, and for k > 1 eigenvalues crossing at once: Brent on
each crossing eigenvalue along the branch parametrised by s = <z - z_a, t_a>; coincident roots
make one event of multiplicity k.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.optimize import brentq

from .corrector import correct
from ..kinds import EventKind
from .results import Event, Point


# Newton iterations within which the fold system converges to roundoff at a quadratic fold
FOLD_QUADRATIC_ITERATIONS = 6


def _done(res, prev, tol):
    # one Newton step more once below tol, so the located p does not depend on the start
    return res <= tol and (prev <= tol or res <= 1e-3 * tol)


def locate_fold(problem, opts, starts, morse, step):
    """Fold near the Points ``starts`` (the bracket's ends, the preferred first); morse = (before,
    after). -> Event: "fold", "soft_fold" (a turn along a soft mode, Morse index unchanged),
    "soft_turn" (nothing to locate), or "branch_point" (F_p orthogonal to the kernel)."""
    if isinstance(starts, Point):
        starts = (starts,)
    ends = sorted(starts, key=lambda q: q.arclength)  # in path order
    found, start, elsewhere = None, starts[0], False
    for start in starts:
        found = _fold_from(problem, opts, start, morse)
        if found is not None and found.ok and not _turn_in_step(found.p, ends):
            # converged to a turn of p outside this step (another fold of a small S)
            found, elsewhere = None, True
            continue
        # a soft critical mode where the Morse index changed: the slide's singular point, not the
        # shape fold next to it; try from the other end
        if found is not None and not (found.ok and found.soft and morse[0] != morse[1]):
            break
    same_morse = morse[0] == morse[1]
    if (found is None or not found.ok) and not same_morse and len(ends) == 2 and (problem.soft_modes is not None
                                                                                   or elsewhere):
        # Newton failed from both ends, or found only a turn outside the step: the shape fold by its
        # own eigenvalue's root along the bracket
        found = _fold_by_bracket(problem, opts, ends[0], ends[1], morse) or found
    if (found is None or not found.ok) and same_morse and len(ends) == 2 and problem.soft_modes is not None:
        # not located from either end: a turn along a soft mode that Newton did not converge to?
        found = _fold_by_bracket(problem, opts, ends[0], ends[1], morse, along_soft=True) or found
    if (found is None or not found.ok) and same_morse and _turns_along_soft(ends):
        # No eigenvalue vanishes: the path turned in p along a soft direction without a singular
        # point to locate; a "soft_turn", crossed like a soft fold.
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
            # the path turned back along a soft mode: no branch end
            return found.event(EventKind.SOFT_FOLD, morse, step, tangent)
        # the Morse index changed, so a shape fold lies in this bracket too (else: not located)
        shape = len(ends) == 2 and _fold_by_bracket(problem, opts, ends[0], ends[1], morse)
        if not shape:
            return found._replace(ok=False).event(EventKind.FOLD, morse, step, tangent)
        found = shape
    fold = found.event(EventKind.FOLD, morse, step, tangent)
    # A fold: Newton converged quadratically, or F_p is clearly transversal to the kernel. Else
    # (v^T F_p -> 0, Newton crawling) it may be a branch point seen from its non-symmetric branch.
    v, Fp = found.vectors[:, found.k], np.asarray(found.Fp)
    if found.ok and (found.iterations <= FOLD_QUADRATIC_ITERATIONS or abs(v @ Fp) > 1e-3 * np.linalg.norm(Fp)):
        return fold
    bp = simple_branch_point(problem, opts, found.u, found.p, v, morse, step, tangent)
    return fold if bp is None else bp


def _turn_in_step(p, ends):
    """Whether p can be the turning point of the path between the Points ends (path order): a
    maximum at least the larger end's p, or a minimum at most the smaller (True for one Point)."""
    if len(ends) != 2:
        return True
    a, b = ends
    slack = 1e-12 * max(1.0, abs(a.p), abs(b.p))
    if a.tangent[-1] > 0.0:
        return p >= max(a.p, b.p) - slack
    return p <= min(a.p, b.p) + slack


class _FoldTry(NamedTuple):
    """A run of the fold system: last iterate (u, p), J, F_p, residual, iterations; J's spectrum,
    k the eigenvalue nearest zero; ok: both within event_tol; soft: ok and the mode is soft."""

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
    """Newton on the fold system from one Point, the border first the smallest shape mode, then,
    if that fails, the smallest mode of all. -> _FoldTry, or None if it diverged."""
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
    """Whether the soft direction's Rayleigh quotient (the ``soft_modes`` hook) is nearer zero than
    every other Ritz value at a located fold."""
    if problem.soft_modes is None:
        return False
    values, _, soft = (np.asarray(a) for a in problem.soft_modes(u, p, vals, vecs))
    soft = soft.astype(bool)
    if not soft.any() or soft.all():
        return False
    return bool(np.min(np.abs(values[soft])) < np.min(np.abs(values[~soft])))


def _null_vector_is_slide(problem, u, p, value, vector):
    """Whether the null vector ``vector`` (n, 1) of J at a located singular point is itself a clean
    slide (the ``soft_modes`` hook on that one vector), i.e. a slide's singular point. Not
    ``_critical_mode_is_soft``: where a shape mode mixes with a slide, the split leaves both
    Ritz values positive at the true singular point."""
    if problem.soft_modes is None:
        return False
    _, _, soft = problem.soft_modes(u, p, np.asarray(value), np.asarray(vector))
    return bool(np.asarray(soft, dtype=bool)[0])


def _shape_spectrum(problem, opts, J, u, p, m):
    """The m lowest eigenpairs of J with the soft directions split off (ascending Ritz pairs), and
    the soft ones (j = 0 without the hook). -> (values, vectors, soft_values, soft_vectors)."""
    if problem.soft_modes is None:
        vals, vecs, _ = problem.backend.spectrum(J, m, problem.n_zero_modes, opts.eig_rtol)
        return vals, vecs, vals[:0], vecs[:, :0]
    vals, vecs, _ = problem.backend.spectrum(J, m + 2, problem.n_zero_modes, opts.eig_rtol)
    values, vectors, soft = (np.asarray(a) for a in problem.soft_modes(u, p, vals, vecs))
    keep = ~soft.astype(bool)
    return values[keep][:m], vectors[:, keep][:, :m], values[~keep], vectors[:, ~keep]


def _on_bracket(problem, opts, a, b, m):
    """(at, s_b): at(s) -> (Correction, ``_shape_spectrum``) of the branch between Points a and b
    corrected on the hyperplane <z - z_a, t_a> = s, 0 <= s <= s_b (smooth through folds and branch
    points while the branch turns by less than 90 degrees). at raises _Failed."""
    be, args = problem.backend, problem.args
    za, zb, ta = a.z, b.z, a.tangent
    sb = float((zb - za) @ ta)
    cache = {}

    def at(s):
        if s not in cache:
            # the chord point on that hyperplane: a second-order predictor
            c = correct(be, lambda u, p: problem.linearise(u, p, args), za + (s / sb) * (zb - za), ta,
                        opts.newton_tol, opts.newton_max_iter)
            if not c.converged:
                raise _Failed
            cache[s] = (c, _shape_spectrum(problem, opts, c.lin[1], c.z[:-1], float(c.z[-1]), m))
        return cache[s]

    return at, sb


def _fold_by_bracket(problem, opts, a, b, morse, along_soft=False):
    """A fold Newton from the bracket's ends missed: Brent on its critical eigenvalue (the lowest
    shape one, or with along_soft the soft direction's) along the bracket, then Newton on the fold
    system from there. -> _FoldTry, or None if not found or not of that kind."""
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
        # Newton did not converge from the root either: the root itself, a point of the branch where
        # the shape eigenvalue vanishes, is the fold
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
    """Euclidean norm of the concatenated parts; inf, silently, when they overflowed."""
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
    # the crossing eigenvalues are counted among the shape modes, as the Morse index is
    at, sb = _on_bracket(problem, opts, a, b, lo + k)
    morse = (a.morse_index, b.morse_index)
    if k == 1:
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
        # The hyperplane corrector may fail right next to a branch point: the unfolded system from
        # the nearest point Brent reached
        s_best = min(tried, key=lambda s: abs(tried[s][1]))
        c, (vals, vecs, _, _) = at(s_best)
        e = _new_branch_point(problem, opts, c.z[:-1], float(c.z[-1]), vecs[:, tried[s_best][0]], morse, step,
                              a.tangent if s_best < 0.5 * sb else b.tangent, known)
        if e is not None:
            return [e]
    return [Event(EventKind.BRANCH_POINT, a.p, a.u, a.eigenvectors[:, lo:lo + k], a.eigenvalues[lo:lo + k], np.inf,
                  calls, k, a.morse_index, b.morse_index, step, a.tangent, False)]


def _new_branch_point(problem, opts, u, p, v, morse, step, tangent, known):
    """simple_branch_point from (u, p) along v, unless it lands on an event in ``known``. (Not
    required to lie in the bracket: the count's band can put a crossing just outside it.)"""
    e = simple_branch_point(problem, opts, u, p, v, morse, step, tangent)
    if e is None or any(_same_point(e, other) for other in known):
        return None
    return e


def _crossing_roots(at, lo, k, sb):
    """The s in (0, sb) where the shape eigenvalues lo .. lo + k - 1 cross zero (Brent). -> (roots or
    None on a failure or no sign change, function calls, tried {s: (index, eigenvalue)})."""
    roots, calls, tried = [], 0, {}
    try:
        for j in range(lo, lo + k):
            def f(s, j=j):  # the shape eigenvalue j on the hyperplane s
                value = at(s)[1][0][j]
                tried[s] = (j, value)
                return value

            lo_s, hi_s = _sign_change(f, sb)
            s, info = brentq(f, lo_s, hi_s, xtol=1e-15 * abs(sb), rtol=1e-15, maxiter=100, full_output=True)
            roots.append(s)
            calls += info.function_calls
    except _Failed:  # a corrector failure, or no sign change
        return None, calls, tried
    return roots, calls, tried


def _sign_change(f, sb):
    """An interval of s where f changes sign: the bracket (0, sb), or else a quarter of it just
    before 0 or just after sb (a crossing within the corrector's noise of an end, where the Morse
    count put it in this bracket and the eigenvalue re-corrected at that end has the other sign).
    Raises _Failed where none does."""
    f0, fb = f(0.0), f(sb)
    if f0 * fb < 0:
        return 0.0, sb
    if f(-0.25 * sb) * f0 < 0:
        return -0.25 * sb, 0.0
    if fb * f(1.25 * sb) < 0:
        return sb, 1.25 * sb
    raise _Failed


def _grouped_events(opts, at, sb, roots, calls, lo, a, b, step):
    """One Event per group of coincident roots: equal to 1e-9 of the bracket, or split only by the
    eigenvalues' noise (every eigenvalue of the group below event_tol at their mean: a symmetric
    crossing in a non-orthonormal gauge)."""
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
