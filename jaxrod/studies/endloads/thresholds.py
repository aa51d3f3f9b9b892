"""Where a straight rod under tension buckles in twist, and the torque plateau of a plectoneme:
the infinite rod's 2 sqrt(BT), the clamped continuum rod's threshold, the discrete rod's own
(``straight_buckling_moment``), and the two-phase plectoneme of hard contact."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...validation import check_positive
from .compiled import rod_hessian
from .force import ForceLoadedRod
from .scene import check_scene, with_end_offset


def tension_twist_threshold(B, T):
    """The infinite rod's buckling moment under tension T: M = 2 sqrt(B T)."""
    return 2.0 * math.sqrt(check_positive("B", B) * check_positive("T", T))


def straight_buckling_moment(rod, T, phi_hi=None, tol=1e-10):
    """The buckling twist of the straight rod ``rod`` (an EndLoadedRod at 0 shortening) under
    tension T (ends held at the stretched length): the phi at which the straight state's lowest
    eigenvalue crosses zero, by Brent's method. Returns (phi_c, M_c = C phi_c / L)."""
    import scipy.linalg  # noqa: PLC0415

    check_scene(rod)
    T = check_positive("T", T)
    C = float(rod.material.C)
    L = float(rod.clamp_length)
    B = float(rod.material.B)
    fr = ForceLoadedRod(rod, "slide")
    ext = float(fr.straight(T)[-1]) * float(rod.length_scale)
    scene = with_end_offset(rod, ext * np.asarray(rod.axis))
    u0 = fr.straight(T, 0.0)[:-1]
    # the straight states all have writhe 0: one neighbourhood serves every phi
    nbr = scene.neighbourhood(np.asarray(scene.from_scaled(u0)), 0.0)

    def low(phi):
        h, _ = rod_hessian(scene, fr.straight(T, phi)[:-1], phi, nbr)
        return float(scipy.linalg.eigh(np.asarray(h), subset_by_index=[0, 0], eigvals_only=True,
                                       driver="evr", check_finite=False)[0])

    # bracket: the threshold lies between the infinite rod's 2 sqrt(BT) and above Greenhill's M L/B
    lo = 0.5 * min(2.0 * math.sqrt(B * T), 8.9868 * B / L) * L / C
    hi = phi_hi if phi_hi is not None else 1.05 * (2.0 * math.sqrt(B * T) + 8.9868 * B / L) * L / C
    f_lo, f_hi = low(lo), low(hi)
    if not (f_lo > 0.0 > f_hi):
        raise ValueError(f"no buckling twist bracketed in [{lo:.4g}, {hi:.4g}] (lowest eigenvalues {f_lo:.3g}, {f_hi:.3g})")
    from scipy.optimize import brentq  # noqa: PLC0415

    phi_c = brentq(low, lo, hi, xtol=tol * hi, rtol=1e-14)
    return phi_c, C * phi_c / L


def _clamped_twist_matrix(m, t, n_quad=64):
    """The 3 x 3 complex matrix whose singularity is the onset of buckling of a straight rod of
    length 1 (B = 1), clamped at both ends, under tension t and axial moment m. Linearised
    Kirchhoff equations for the complex tangent deviation v = x' + i y':
    v'' - i m v' - t v = const, so v = c0 + e^{i a s} (c1 cosh(b s) + c2 sinh(b s) / b) with
    a = m / 2, b = sqrt(t - m^2/4) (complex past 2 sqrt t; the basis is smooth through b = 0);
    clamped ends: v(0) = v(1) = 0 and integral_0^1 v ds = 0 (the ends stay on the axis)."""
    a = 0.5 * m
    b = np.sqrt(complex(t - 0.25 * m * m))
    b = b if abs(b) > 1e-12 else 1e-12

    def f(s):
        s = np.asarray(s, dtype=float)
        e = np.exp(1j * a * s)
        if abs(b) < 5.0:
            return np.stack([np.ones_like(s, dtype=complex), e * np.cosh(b * s), e * np.sinh(b * s) / b], axis=-1)
        # large |b| (long rods): the same span with columns bounded on [0, 1] (no overflow)
        return np.stack([np.ones_like(s, dtype=complex), e * np.exp(b * (s - 1.0)), e * np.exp(-b * s)], axis=-1)

    x, w = np.polynomial.legendre.leggauss(max(n_quad, int(4 * abs(b)) + 16))
    integral = 0.5 * np.sum(w[:, None] * f(0.5 * (x + 1.0)), axis=0)
    return np.stack([f(0.0), f(1.0), integral], axis=0)


def _clamped_twist_matrices(ms, t, n_quad=64):
    """``_clamped_twist_matrix`` for an array of m (K,) at once: (K, 3, 3) (the scan's batch;
    quadrature with the batch's largest point count)."""
    ms = np.asarray(ms, dtype=float)
    a = 0.5 * ms
    b = np.sqrt((t - 0.25 * ms * ms).astype(complex))
    b = np.where(np.abs(b) > 1e-12, b, 1e-12)
    x, w = np.polynomial.legendre.leggauss(max(n_quad, int(4 * np.max(np.abs(b))) + 16))
    small = (np.abs(b) < 5.0)[:, None]

    def f(s):  # (K, n_s, 3) at points s (n_s,)
        s = np.asarray(s, dtype=float)[None, :]
        bb, e = b[:, None], np.exp(1j * a[:, None] * s)
        with np.errstate(all="ignore"):
            c1 = np.where(small, np.cosh(bb * s), np.exp(bb * (s - 1.0)))
            c2 = np.where(small, np.sinh(bb * s) / bb, np.exp(-bb * s))
        return np.stack([np.ones_like(e), e * c1, e * c2], axis=-1)

    integral = 0.5 * np.einsum("q,kqj->kj", w, f(0.5 * (x + 1.0)))
    return np.stack([f([0.0])[:, 0], f([1.0])[:, 0], integral], axis=1)


def clamped_tension_twist_threshold(B, T, L, n_scan=400):
    """The buckling moment M_c of a straight rod of length L clamped at both ends under tension T
    (continuum, inextensible): the smallest m = M L / B at which ``_clamped_twist_matrix`` is
    singular, found by scanning its smallest singular value and refining the first zero. Tends to
    Greenhill's 8.9868 B / L as T -> 0 and to 2 sqrt(B T) as L sqrt(T / B) -> infinity."""
    from scipy.optimize import minimize_scalar  # noqa: PLC0415

    B, T, L = check_positive("B", B), check_positive("T", T), check_positive("L", L)
    t = T * L * L / B
    sig = lambda m: float(np.linalg.svd(_clamped_twist_matrix(m, t), compute_uv=False)[-1])  # noqa: E731
    hi = 2.0 * math.sqrt(t) + 12.0
    grid = np.linspace(0.05 * hi, hi, max(n_scan, min(int(50 * hi), 40000)))
    n_scan = grid.size
    vals = np.linalg.svd(_clamped_twist_matrices(grid, t), compute_uv=False)[:, -1]
    scale = np.max(vals)
    for i in range(1, n_scan - 1):
        if vals[i] <= vals[i - 1] and vals[i] <= vals[i + 1]:
            res = minimize_scalar(sig, bounds=(grid[i - 1], grid[i + 1]), method="bounded",
                                  options={"xatol": 1e-10 * hi})
            if res.fun < 1e-4 * scale:
                # polish: Gauss-Newton on |det|^2 (det is analytic, with a complex slope at the root)
                det = lambda m: np.linalg.det(_clamped_twist_matrix(m, t))  # noqa: E731
                m = res.x
                for _ in range(20):
                    dm = 1e-6 * max(1.0, abs(m))
                    slope = (det(m + dm) - det(m - dm)) / (2.0 * dm)
                    step = -float(np.real(np.conj(slope) * det(m))) / float(abs(slope) ** 2)
                    m += step
                    if abs(step) < 1e-14 * max(1.0, abs(m)):
                        break
                if sig(m) < 1e-9 * scale:
                    return m * B / L
    raise ValueError(f"no buckling moment found below m = {hi:.4g} (t = {t:.4g})")


# ---------------------------------------------------------------------- plectonemes
@dataclass(frozen=True)
class Plectoneme:
    """The hard-contact two-phase plectoneme at tension T (``plectoneme_plateau``): M the plateau
    torque, alpha the superhelix angle (rad, strand tangent to the plectoneme axis), r = D/2, slope
    d(extension)/d(turns) = -4 pi r / sin 2 alpha, writhe_per_length sin 2 alpha / (4 pi r)."""

    M: float
    alpha: float
    r: float
    slope: float
    writhe_per_length: float


def plectoneme_plateau(B, T, D):
    """The torque plateau of a plectoneme of a rod of bending stiffness B and diameter D under
    tension T, in the two-phase model with hard contact: two strands wound at radius r = D/2 about
    the plectoneme axis with helix angle alpha (curvature sin^2 alpha / r, writhe sin 2 alpha /
    (4 pi r) per length), coexisting with straight tails; the end loop neglected (long plectonemes).
    Per length, at torque M, the plectoneme's B sin^4 alpha / (2 r^2) - M sin 2 alpha / (2 r) equals
    the straight phase's -T, stationary in alpha:

        M r / B = 2 sin^3 alpha cos alpha / cos 2 alpha,
        T r^2 / B = sin^4 alpha (1 + 2 cos^2 alpha) / (2 cos 2 alpha).

    For T r^2 / B -> 0, M -> 2 (2/3)^(3/4) B^(1/4) T^(3/4) r^(1/2) (alpha^4 ~ 2 T r^2 / 3 B)."""
    from scipy.optimize import brentq  # noqa: PLC0415

    B, T, D = check_positive("B", B), check_positive("T", T), check_positive("D", D)
    r = 0.5 * D
    tau = T * r * r / B

    def f(a):
        return math.sin(a) ** 4 * (1.0 + 2.0 * math.cos(a) ** 2) / (2.0 * math.cos(2.0 * a)) - tau

    a = brentq(f, 1e-12, math.pi / 4.0 - 1e-12, xtol=1e-15, rtol=1e-15)
    M = 2.0 * B * math.sin(a) ** 3 * math.cos(a) / (r * math.cos(2.0 * a))
    return Plectoneme(M=M, alpha=a, r=r, slope=-4.0 * math.pi * r / math.sin(2.0 * a),
                      writhe_per_length=math.sin(2.0 * a) / (4.0 * math.pi * r))


# Edges per core width L / lambda of the localized helix, and the largest twist per edge (rad),
