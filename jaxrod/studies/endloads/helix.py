"""The localized helical buckle of a long rod under tension and twist: Neukirch, van der Heijden
and Thompson 2002 (NvdHT; J. Mech. Phys. Solids 50, eqs. 14-15), the analytic reference of the
end-loaded rods of ``jaxrod.studies.endloads``, and where it applies.

With m = M L/B, t = T L^2/B, gamma = C/B, lambda = sqrt(t - m^2/4) and s measured from the rod's
midpoint, the tangent's angle theta to the axis and its azimuth psi obey

    1 - cos theta = (2 lambda^2 / t) sech^2(lambda s / L),    psi' = (m / L) / (1 + cos theta),

from the first integrals B/2 (theta'^2 + psi'^2 sin^2 theta) + T cos theta = T and
B psi' sin^2 theta + M cos theta = M (twisting moment M3 = M); integrating gives the end shortening
d L = integral (1 - cos theta) ds = 4 lambda L / t, the largest angle cos theta_max = m^2/(2t) - 1,
and the end rotation R = m / gamma (twist) + 4 arccos(m / (2 sqrt t)) (2 pi times the ray-closed
writhe of the loop).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...validation import check_finite, check_positive

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class LocalizedHelix:
    """The localized helical buckle of NvdHT 2002 for (m, t, gamma): lam = sqrt(t - m^2/4), end
    rotation R (rad), end shortening d (per length), theta_max, writhe Wr (ray-closed, infinite
    rod) = (2/pi) arccos(m / (2 sqrt t)), twist Tw = m / (2 pi gamma)."""

    m: float
    t: float
    gamma: float
    lam: float
    R: float
    d: float
    theta_max: float
    Wr: float
    Tw: float


def localized_helix(m, t, gamma):
    """NvdHT 2002 eqs. 14-15 for m = ML/B, t = TL^2/B, gamma = C/B (needs m^2 < 4t). Either sign
    of m: the mirror image (x, y, z) -> (x, -y, z) of the loop with moment m is the loop with -m
    at the same t, its end rotation and writhe of the opposite sign, R(-m) = -R(m) (eq. 14 as
    printed, R = m/gamma + 4 arccos(m / 2 sqrt t), is the m > 0 branch)."""
    m, t, gamma = check_finite("m", m), check_positive("t", t), check_positive("gamma", gamma)
    if not m * m < 4.0 * t:
        raise ValueError(f"need m^2 < 4 t (below the straight rod's threshold M = 2 sqrt(BT)), got m = {m}, t = {t}")
    lam = localization_parameter(m, t)
    sign = math.copysign(1.0, m)
    ac = math.acos(abs(m) / (2.0 * math.sqrt(t)))
    return LocalizedHelix(m=m, t=t, gamma=gamma, lam=lam, R=m / gamma + sign * 4.0 * ac,
                          d=math.sqrt(16.0 / t * (1.0 - m * m / (4.0 * t))),
                          theta_max=math.acos(m * m / (2.0 * t) - 1.0), Wr=sign * 2.0 * ac / math.pi,
                          Tw=m / (TWO_PI * gamma))


def localized_helix_from_shortening(d, R, gamma):
    """The (m, t) of every localized helix with end shortening d (per length) and end rotation R
    (rad) at gamma, from NvdHT eqs. 14-15: with u = d^2 t / 16 in (0, 1), m = 8 sqrt(u(1-u)) / d and
    |R| = |m| / gamma + 4 arcsin(sqrt u), solved for u (all roots), m taking the sign of R.
    Returns a list of LocalizedHelix, ascending in t (none for R = 0)."""
    from scipy.optimize import brentq  # noqa: PLC0415

    d, gamma = check_positive("d", d), check_positive("gamma", gamma)
    if not d < 1.0:
        raise ValueError(f"d (end shortening / L) must be below 1, got {d!r}")
    R = check_finite("R", R)
    sign, R = math.copysign(1.0, R), abs(R)

    def f(u):
        return 8.0 * math.sqrt(u * (1.0 - u)) / (d * gamma) + 4.0 * math.asin(math.sqrt(u)) - R

    grid = np.linspace(1e-12, 1.0 - 1e-12, 4001)
    vals = np.array([f(u) for u in grid])
    out = []
    for i in np.nonzero(np.sign(vals[:-1]) * np.sign(vals[1:]) <= 0)[0]:
        u = brentq(f, grid[i], grid[i + 1], xtol=1e-15, rtol=1e-15)
        t = 16.0 * u / d ** 2
        if out and abs(t / out[-1].t - 1.0) < 1e-9:  # a root on a grid point, found from both sides
            continue
        out.append(localized_helix(sign * 8.0 * math.sqrt(u * (1.0 - u)) / d, t, gamma))
    return out


# ---------------------------------------------------------------------- where the formulas hold
# NvdHT's loop is on an infinite, inextensible rod: the reference of a clamped rod while the
# finite length's error (~ e^-lambda, 2e-6 at 13) and the stretch's are small.
LOCALIZATION_MIN = 13.0
# The largest relative shift of t by the stretch (``stretch_shift``) for the formulas to stand.
STRETCH_SHIFT_MAX = 1e-4


def localization_parameter(m, t):
    """The localization parameter lambda = sqrt(t - m^2/4) of NvdHT's loop (m = ML/B, t = TL^2/B;
    0 where m^2 >= 4t: no loop). The loop's core is L/lambda wide, so a clamped rod of length L
    differs from the infinite one by O(e^-lambda)."""
    m, t = float(m), float(t)
    return math.sqrt(max(t - 0.25 * m * m, 0.0))


def stretch_shift(ref, ea):
    """First-order estimate of the relative change of t = TL^2/B that stretching causes at the
    imposed (d, R) of the localized helix ``ref``, for a rod of stretch stiffness ea = EA L^2/B
    (None or inf: inextensible, 0): the inextensible loop of the stretched length L(1 + eps),
    eps = t/ea, at the same end distance has shortening d' = (d + eps)/(1 + eps), solved at fixed R
    (the root nearest ref)."""
    if ea is None or math.isinf(ea):
        return 0.0
    ea = check_positive("ea", ea)
    eps = ref.t / ea
    d2 = (ref.d + eps) / (1.0 + eps)
    if not d2 < 1.0:
        return math.inf
    found = localized_helix_from_shortening(d2, ref.R, ref.gamma) if ref.R != 0.0 else []
    if not found:
        return math.inf
    t2 = min(found, key=lambda h: abs(h.t - ref.t)).t
    return abs(t2 / (1.0 + eps) ** 2 / ref.t - 1.0)


@dataclass(frozen=True)
class ReferenceCheck:
    """Whether NvdHT's formulas are the reference of a clamped rod at ``LocalizedHelix`` ref:
    valid, and the reasons (tuple of str, empty when valid) otherwise; lam the localization
    parameter, stretch = T/EA, shift the estimated relative change of t by the stretch."""

    valid: bool
    reasons: tuple
    lam: float
    stretch: float
    shift: float

    @property
    def reason(self):
        """The reasons in one line, or None when valid."""
        return "; ".join(self.reasons) if self.reasons else None


def reference_check(ref, ea=None):
    """``ReferenceCheck`` of the localized helix ``ref`` (``localized_helix``) as the reference of
    a clamped rod of length L with stretch stiffness ea = EA L^2/B (None: inextensible): valid
    when the loop is localized (lambda >= ``LOCALIZATION_MIN``) and the stretch shifts t by less
    than ``STRETCH_SHIFT_MAX`` (``stretch_shift``)."""
    lam = localization_parameter(ref.m, ref.t)
    reasons = []
    if lam < LOCALIZATION_MIN:
        reasons.append(f"not localized: lambda = sqrt(t - m^2/4) = {lam:.3g} < {LOCALIZATION_MIN:g} (the formulas "
                       f"are for a loop much shorter than the rod; its tails reach the clamps, error ~ e^-lambda)")
    stretch = 0.0 if ea is None or math.isinf(ea) else ref.t / float(ea)
    shift = stretch_shift(ref, ea)
    if shift > STRETCH_SHIFT_MAX:
        reasons.append(f"extensible: the stretch T/EA = {stretch:.2g} shifts t by ~{shift:.1e} "
                       f"(> {STRETCH_SHIFT_MAX:g}; the formulas are for an inextensible rod)")
    return ReferenceCheck(valid=not reasons, reasons=tuple(reasons), lam=lam, stretch=stretch, shift=shift)


def localized_helix_curve(m, t, s, L=1.0):
    """The localized helix's tangent angle theta(s), azimuth psi(s) and centreline r(s) (n, 3) at
    arc lengths s (n,) from the midpoint (ascending), for a rod of length L along z, the tails on
    the z axis. Integrated with DOP853 (rtol 1e-12)."""
    from scipy.integrate import solve_ivp  # noqa: PLC0415

    localized_helix(m, t, 1.0)  # m finite, t positive, m^2 < 4 t
    L = check_positive("L", L)
    s = np.asarray(s, dtype=float)
    if not np.all(np.isfinite(s)):
        raise ValueError("s must be finite")
    lam = localization_parameter(m, t)
    c = 2.0 * lam * lam / t

    def one_minus_cos(x):
        return c / np.cosh(lam * x / L) ** 2

    def rhs(x, y):
        om = one_minus_cos(x)
        ct = 1.0 - om
        st = math.sqrt(max(om * (2.0 - om), 0.0))
        psi = y[3]
        return [st * math.cos(psi), st * math.sin(psi), ct, (m / L) / (2.0 - om)]

    # integrate outwards from the midpoint both ways (psi(0) = 0, r(0) = 0), then shift the tails to the axis
    far = 40.0 * L / lam  # sech^2 ~ e^-80 there: the tails are straight
    out = {}
    for sign in (1.0, -1.0):
        span = (0.0, sign * max(far, float(np.max(np.abs(s)))))
        sol = solve_ivp(rhs, span, [0.0, 0.0, 0.0, 0.0], method="DOP853", rtol=1e-12, atol=1e-14, dense_output=True)
        out[sign] = sol
    tail = out[1.0].sol(max(far, float(np.max(np.abs(s)))))
    y = np.empty((s.size, 4))
    pos = s >= 0
    if np.any(pos):
        y[pos] = out[1.0].sol(s[pos]).T
    if np.any(~pos):
        y[~pos] = out[-1.0].sol(s[~pos]).T
    r = y[:, :3].copy()
    r[:, :2] -= tail[:2]
    theta = np.arccos(np.clip(1.0 - one_minus_cos(s), -1.0, 1.0))
    return theta, y[:, 3], r


# ---------------------------------------------------------------------- the roots at imposed ends
def named_helix_roots(found):
    """(name, LocalizedHelix) for the helices ``found`` (ascending in t): "only" for one root, else
    "small" and "large" for the first two and "t2", "t3", ... for any further ones."""
    names = ["only"] if len(found) == 1 else ["small", "large"] + [f"t{i}" for i in range(2, len(found))]
    return list(zip(names, found))


def select_helix_roots(named, root):
    """The named roots (``named_helix_roots``) to solve for the choice ``root``: "small" or
    "large" keeps the first or last of several, anything else ("stable", "both") all of them."""
    if root in ("small", "large") and len(named) > 1:
        return [named[0] if root == "small" else named[-1]]
    return list(named)


def nearest_localized_helix(d, R, gamma, m, t):
    """The localized helix at end shortening d (per length) and end rotation R (rad) nearest the
    computed loads m = ML/B, t = TL^2/B (of the two branches meeting at the fold in R, the one
    with the least |t_h/t - 1| + |m_h/m - 1|), or None where there is none at (d, R)."""
    found = localized_helix_from_shortening(d, R, gamma)
    return min(found, key=lambda x: abs(x.t / t - 1) + abs(x.m / m - 1)) if found else None
