"""An open overhand (trefoil) knot tied in a rod clamped at both ends and pulled tight.

Scene: an ``EndLoadedRod`` (``shortened_rod``) with soft self-contact, both clamps on one axis,
the far clamp ``excess`` closer than one rod length, its frame turned by ``phi``. The knot is the
trefoil (sin t + 2 sin 2t, cos t - 2 cos 2t, sin 3t) cut open at the tip of one lobe (t in
[pi + delta, 3 pi - delta]), scaled to the loop size, with two straight tails along the axis, so
the rod closed by rays along the axis is a trefoil.

Pulling is displacement controlled (robust with contact): the excess length e = L - end distance
decreases step by step, each state is ``relax``ed from the last, and the tension T is read from
``end_loads``.

The loose limit (Audoly, Clauvelin & Neukirch, PRL 99, 164301, 2007; Clauvelin, Audoly & Neukirch,
J. Mech. Phys. Solids 2009): the loop tends to a circle of radius R with T = B / (2 R^2), so the
end-shortening of an inextensible rod tends to 2 pi R = pi sqrt(2) sqrt(B/T) (``LOOSE_LIMIT``), with
corrections in powers of eps = sqrt(h/R), h = D/2 the rod's radius (``loose_parameter``); the
contact set is an interval flanked by two isolated contact points (``contact_runs``). jaxrod's
excess L - end distance includes the axial stretch; ``inextensible_excess`` takes it out.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .endloads import end_loads, shortened_rod, with_shortening
from ..model.material import Material
from ..validation import check_finite, check_int_at_least, check_positive

__all__ = ["open_overhand_knot", "OpenKnotOptions", "KnotState", "moved_to_excess", "pull", "loop_height", "loop_span",
           "relax_knot", "fit_prefactor", "fit_loose_limit", "mean_tension", "LOOSE_LIMIT", "loose_parameter",
           "inextensible_excess", "apex_radius", "contact_runs"]

TWO_PI = 2.0 * math.pi
DEFAULT_CONTACT_STIFFNESS = 100.0
# The published leading order of a loose frictionless knot, scaled by sqrt(T/B): the inextensible
# end-shortening 2 pi R and the loop radius R, with R = sqrt(B / (2 T)).
LOOSE_LIMIT = {"excess": math.pi * math.sqrt(2.0), "loop_radius": 1.0 / math.sqrt(2.0)}


def _trefoil(t):
    return np.stack([np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), np.sin(3 * t)], axis=-1)


def _open_curve(loop, tail, delta=0.3, n=4000):
    """Polyline (n', 3) of the open knot in its own frame (tails along +X), scaled so the trefoil's
    unit is ``loop``; the tails reach X = -tail and X = +tail on the line Y = Z = 0."""
    t = np.linspace(math.pi + delta, 3 * math.pi - delta, n)
    k = (_trefoil(t) - np.array([0.0, -3.0, 0.0])) * loop  # tip of the lobe at the origin
    a = np.array([-tail, 0.0, 0.0])
    b = np.array([tail, 0.0, 0.0])
    m = max(50, n // 10)
    t1 = a[None, :] + np.linspace(0.0, 1.0, m)[:-1, None] * (k[0] - a)[None, :]
    t2 = k[-1][None, :] + np.linspace(0.0, 1.0, m)[1:, None] * (b - k[-1])[None, :]
    return np.concatenate([t1, k, t2], axis=0)


def _arclength(p):
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


@dataclass(frozen=True)
class OpenKnotOptions:
    """How ``open_overhand_knot`` builds the knot (B, delta and Lk0 checked on construction; a
    ValueError names the wrong one).

    B, nu: the material's bending stiffness and Poisson ratio (EA = 16 B / D^2).
    contact_stiffness: kappa_c of the soft self-contact.
    delta: where the trefoil is cut open, the arc t in [pi + delta, 3 pi - delta] (0.05 ... 1).
    Lk0: the rod's linking number at phi = 0, an integer; None: 3 with the sign of the drawn
      curve's writhe (the loose knot's writhe), so phi = 0 is the nearly twist-free knot.
    contact_quadrature: Gauss points per segment of the contact integral (with 2, T(e) jumps as
      strands slide past the nodes).
    """

    B: float = 1.0
    nu: float = 0.5
    contact_stiffness: float = DEFAULT_CONTACT_STIFFNESS
    delta: float = 0.3
    Lk0: int | None = None
    contact_quadrature: int = 3

    def __post_init__(self):
        check_positive("B", self.B)
        if not 0.05 <= self.delta <= 1.0:
            raise ValueError(f"delta must lie in [0.05, 1], got {self.delta!r}")
        if self.Lk0 is not None:
            check_int_at_least("Lk0", self.Lk0, -10 ** 6)


def _check_knot_size(N, L, D, loop, delta):
    """The knot's sizes as floats and N as an int, or ValueError naming the one that is wrong."""
    L, D, loop = check_positive("L", L), check_positive("D", D), check_positive("loop", loop)
    N = check_int_at_least("N", N, 40)
    if L / (N - 2) > D:
        raise ValueError(f"N = {N} gives edges of {L / (N - 2) / D:.2f} D: self-contact needs edges no longer "
                         f"than the diameter, N >= L/D + 2 = {math.ceil(L / D) + 2}")
    if 2.0 * loop * (3.0 * math.sin(3 * delta) + 0.0) < 1.2 * D:
        raise ValueError(f"loop = {loop:g} is too small for D = {D:g}: the tails would touch at the cut")
    knot_len = _arclength(_open_curve(loop, 0.0, delta))[-1]
    if 0.5 * (L - knot_len) < 12.0 * loop:
        raise ValueError(f"loop = {loop:g} is too large for L = {L:g}: the knot needs {knot_len:.3g} of rod and "
                         "each tail at least 12 loop lengths")
    return N, L, D, loop


def _drawn_knot(L, loop, delta):
    """The open knot drawn with arc length L: (polyline (n, 3) from the origin with its tails along
    z, its arc length at each point (n,)), the tails' half-width found by bisection."""
    lo, hi = 0.0, L
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if _arclength(_open_curve(loop, mid, delta))[-1] < L:
            lo = mid
        else:
            hi = mid
    p = _open_curve(loop, 0.5 * (lo + hi), delta)
    s = _arclength(p)
    # own frame (X, Y, Z) -> space (Y, Z, X): a cyclic permutation (proper rotation), tails along z
    return p[:, [1, 2, 0]] - p[0, [1, 2, 0]][None, :], s


def open_overhand_knot(N, L, D, loop, phi=0.0, options=None):
    """(scene, q0): an open overhand knot of rest length L (between the clamps' points) and
    diameter D, N nodes, clamped on the z axis; ``loop``: the trefoil's unit length (its
    lobes are ~6 loop across); material, contact and linking number from ``options``
    (``OpenKnotOptions``; None: the defaults). The far clamp sits where the drawn curve ends, and
    Tw = Lk0 + phi / 2 pi - Wr is spread evenly. Refused (naming the parameter): N < 40 or edges longer than D,
    non-positive L, D, loop, a knot too long for the rod (tails shorter than 12 loops)."""
    import jax.numpy as jnp  # noqa: PLC0415

    options = OpenKnotOptions() if options is None else options
    phi = check_finite("phi", phi)
    N, L, D, loop = _check_knot_size(N, L, D, loop, options.delta)
    p, s = _drawn_knot(L, loop, options.delta)
    excess = L - p[-1, 2]
    mat = Material.from_ratio(B=options.B, nu=options.nu, D=D)
    scene = shortened_rod(N, L, mat, shortening=excess, contact_stiffness=options.contact_stiffness,
                          contact_quadrature=options.contact_quadrature)
    h = L / (N - 2)
    si = (np.arange(N) - 0.5) * h
    x = np.stack([np.interp(si, s, p[:, j]) for j in range(3)], axis=1)
    xc = np.asarray(scene.x_clamped)
    x[:2] = xc[:2]
    x[-2:] = xc[2:] + np.asarray(scene.end_offset)[None, :]
    q = np.concatenate([x[2:N - 2].ravel(), np.zeros(N - 3)])
    xfull = np.asarray(scene.nodes(jnp.asarray(q)))
    wr = float(scene.exact_writhe(jnp.asarray(xfull)))
    Lk0 = float(3 * np.sign(wr)) if options.Lk0 is None else float(options.Lk0)
    scene = dataclasses.replace(scene, Lk0=Lk0, q_init=jnp.asarray(q))
    # twist angles: theta_end = phi + end angle (on the branch Tw = Lk0 + phi/2pi - Wr), spread evenly
    theta_end = phi + float(scene.end_angle(jnp.asarray(xfull)))
    n_edges = N - 1
    q[3 * (N - 4):] = theta_end * np.arange(1, n_edges - 1) / (n_edges - 1)
    return scene, q


def loop_height(scene, x):
    """Largest distance of the nodes x (N, 3) from the clamp axis (the line through the near clamp)."""
    a = np.asarray(scene.axis, dtype=float)
    r = np.asarray(x, dtype=float) - np.asarray(scene.x_clamped, dtype=float)[0][None, :]
    lat = r - (r @ a)[:, None] * a[None, :]
    return float(np.max(np.linalg.norm(lat, axis=1)))


def loop_span(scene, x, fraction=0.3):
    """The loop's diameter: the largest distance between two nodes of x (N, 3) that lie further
    from the clamp axis than ``fraction`` of the largest such distance (``loop_height``), a
    threshold that scales with the loop."""
    a = np.asarray(scene.axis, dtype=float)
    x = np.asarray(x, dtype=float)
    r = x - np.asarray(scene.x_clamped, dtype=float)[0][None, :]
    lat = np.linalg.norm(r - (r @ a)[:, None] * a[None, :], axis=1)
    p = x[lat > fraction * lat.max()] if lat.max() > 0 else x[:0]
    if len(p) < 2:
        return 0.0
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
    return float(d.max())


@dataclass(frozen=True)
class KnotState:
    """One pulled state: excess (L - end distance), T, M (axial end moment), height, span, phi, Wr,
    Tw, Lk, morse (negative eigenvalues), lowest (lowest eigenvalues, scaled), contacts (touching
    segment pairs), energy, q (DOFs), x (nodes)."""

    excess: float
    T: float
    M: float
    height: float
    span: float
    phi: float
    Wr: float
    Tw: float
    Lk: float
    morse: int
    lowest: np.ndarray
    contacts: int
    energy: float
    q: np.ndarray
    x: np.ndarray


def relax_knot(scene, phi, q0, previous=None, gtol=1e-7, k=6):
    """Relax the knot at its current excess length and end rotation phi; a ``KnotState``."""
    import jax.numpy as jnp  # noqa: PLC0415

    from ..model.contact import contact_count  # noqa: PLC0415
    from ..linalg.stability import CONTACT_NEGATIVE_TOL  # noqa: PLC0415
    from ..solve.equilibrium import RelaxOptions, relax  # noqa: PLC0415

    e = relax(scene, phi, q0, RelaxOptions(gtol=gtol, k=k, negative_tol=CONTACT_NEGATIVE_TOL, max_rounds=400),
              previous=previous)
    loads = end_loads(scene, e.q, phi, e.neighbourhood)
    nbr = e.neighbourhood
    nc = int(contact_count(jnp.asarray(e.x), nbr.pairs, nbr.mask, False, float(scene.material.D)))
    return e, KnotState(excess=float(scene.shortening), T=loads.T, M=loads.M, height=loop_height(scene, e.x),
                        span=loop_span(scene, e.x),
                        phi=float(phi), Wr=float(e.Wr), Tw=float(e.Tw), Lk=float(e.Lk),
                        morse=int(e.stability.n_negative), lowest=np.asarray(e.stability.eigenvalues),
                        contacts=nc, energy=float(e.energy), q=np.asarray(e.q), x=np.asarray(e.x))


def moved_to_excess(scene, q, new_excess):
    """(scene at the new excess, q with the far tail stretched): every interior node moved along
    the axis in proportion to its height along it, so no edge next to the far clamp is torn."""
    old = float(scene.shortening)
    new = with_shortening(scene, float(new_excess))
    n_free = scene.n_nodes - 4
    q = np.array(q, dtype=float)
    xi = q[:3 * n_free].reshape(n_free, 3)
    a = np.asarray(scene.axis, dtype=float)
    z0 = np.asarray(scene.x_clamped, dtype=float)[1] @ a
    z = xi @ a - z0
    span = float(scene.end_distance) - (np.asarray(scene.x_clamped, dtype=float)[1] @ a - np.asarray(scene.x_clamped, dtype=float)[0] @ a)
    frac = np.clip(z / max(span, 1e-300), 0.0, 1.0)
    xi = xi + (old - float(new_excess)) * frac[:, None] * a[None, :]
    q[:3 * n_free] = xi.ravel()
    return new, q


def pull(scene, q0, excesses, phi=0.0, progress=None, gtol=1e-7, previous=None):
    """Pull the knot: relax at each excess length in ``excesses`` (any order; normally decreasing,
    which raises T), each from the last state. Returns a list of ``KnotState``. Stops (returning
    what it has) at a ``TopologyChangeError`` or a relaxation that fails, reported by ``progress``.
    Refused: an excess outside (0, L), non-finite phi."""
    from ..solve.solvers import ConvergenceError  # noqa: PLC0415
    from ..solve.equilibrium import TopologyChangeError  # noqa: PLC0415

    phi = check_finite("phi", phi)
    L = float(scene.clamp_length)
    ex = [check_finite("excesses", v) for v in np.atleast_1d(excesses)]
    for v in ex:
        if not 0.0 < v < L:
            raise ValueError(f"excesses must lie in (0, L) = (0, {L:g}), got {v!r}")
    say = progress or (lambda s: None)
    out = []
    prev = previous  # an Equilibrium or KnotState: its writhe guards the first relaxation
    q = np.asarray(q0, dtype=float)
    for v in ex:
        scene, q = moved_to_excess(scene, q, v)
        try:
            prev, st = relax_knot(scene, phi, q, previous=prev, gtol=gtol)
        except (ConvergenceError, TopologyChangeError) as exc:
            say(f"excess {v:.4g}: stopped ({type(exc).__name__}: {exc})")
            break
        q = st.q
        out.append(st)
        say(f"excess {v:.4g}: T = {st.T:.4g}, span = {st.span:.4g}, height = {st.height:.4g}, Lk = {st.Lk:.6f}, Wr = {st.Wr:.4f}, "
            f"morse = {st.morse}, contacts = {st.contacts}")
    return out


def fit_prefactor(T, y, B=1.0):
    """Fit y = c sqrt(B/T) (least squares in log) and the free power law y = a T^-p.
    Returns (c, c_std, p, p_std): c's scatter from the residuals, p's from the slope fit."""
    T, y = np.asarray(T, dtype=float), np.asarray(y, dtype=float)
    lt, ly = np.log(T), np.log(y)
    logc = ly + 0.5 * (lt - math.log(B))
    c = float(np.exp(np.mean(logc)))
    c_std = float(c * np.std(logc, ddof=1) / math.sqrt(len(logc))) if len(logc) > 1 else float("nan")
    A = np.stack([np.ones_like(lt), lt], axis=1)
    coef, res, *_ = np.linalg.lstsq(A, ly, rcond=None)
    p = -float(coef[1])
    if len(lt) > 2:
        r = ly - A @ coef
        s2 = float(r @ r) / (len(lt) - 2)
        cov = s2 * np.linalg.inv(A.T @ A)
        p_std = float(math.sqrt(cov[1, 1]))
    else:
        p_std = float("nan")
    return c, c_std, p, p_std


def fit_loose_limit(x, c, degree=1):
    """The loose-knot limit c(0) of a scale-free measure c = y sqrt(T/B), a function of one
    variable for a long rod: x = D sqrt(T/B), or the expansion parameter eps (``loose_parameter``),
    in which the published asymptotics go. Fits c = c0 + c1 x (+ c2 x^2 with degree 2) by least
    squares. Returns (coefficients (degree+1,), their standard errors, the largest residual)."""
    x, c = np.asarray(x, dtype=float), np.asarray(c, dtype=float)
    A = np.stack([x ** k for k in range(degree + 1)], axis=1)
    coef, *_ = np.linalg.lstsq(A, c, rcond=None)
    r = c - A @ coef
    dof = len(c) - degree - 1
    if dof > 0:
        cov = float(r @ r) / dof * np.linalg.inv(A.T @ A)
        err = np.sqrt(np.diag(cov))
    else:
        err = np.full(degree + 1, np.nan)
    return coef, err, float(np.max(np.abs(r)))


def mean_tension(excess, energy):
    """The mean tension over each step of a displacement-controlled pull: T = -dE/de between
    consecutive states, (E1 - E0) / (e0 - e1), placed at the geometric mean sqrt(e0 e1) of their
    excess lengths (exact for the loose-knot law T = c^2 B / e^2); smoother than ``end_loads``'s
    tension, which ripples as strands slide past the nodes. excess, energy: (K,) in any order.
    Returns (e_mid (K-1,), T_mean (K-1,)), sorted by excess."""
    e, E = np.asarray(excess, dtype=float), np.asarray(energy, dtype=float)
    order = np.argsort(e)
    e, E = e[order], E[order]
    return np.sqrt(e[1:] * e[:-1]), -(E[1:] - E[:-1]) / (e[1:] - e[:-1])


def loose_parameter(D, T, B=1.0):
    """The loose-knot expansion parameter eps = sqrt(h / R): h = D/2 the rod's radius, R =
    sqrt(B / (2 T)) the leading-order loop radius. D, T: scalars or arrays of equal shape."""
    T = np.asarray(T, dtype=float)
    return np.sqrt(0.5 * np.asarray(D, dtype=float) * np.sqrt(2.0 * T / B))


def inextensible_excess(x):
    """Arc length minus end distance of the polyline x (N, 3): the end-shortening of an
    inextensible rod in the same shape (the published one), without the axial stretch T L / EA
    that ``KnotState.excess`` includes."""
    x = np.asarray(x, dtype=float)
    return float(np.sum(np.linalg.norm(np.diff(x, axis=0), axis=1)) - np.linalg.norm(x[-1] - x[0]))


def apex_radius(x, half_arc):
    """The loop's radius at its apex: the circle through the node furthest from the end-to-end
    line of x (N, 3) and the nodes ``half_arc`` of arc length before and after it (a length of the
    order of the loop radius, so node-scale ripples average out)."""
    x = np.asarray(x, dtype=float)
    axis = (x[-1] - x[0]) / np.linalg.norm(x[-1] - x[0])
    r = x - x[0]
    i = int(np.argmax(np.linalg.norm(r - (r @ axis)[:, None] * axis[None, :], axis=1)))
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(x, axis=0), axis=1))])
    a = x[max(int(np.searchsorted(s, s[i] - half_arc)), 0)]
    b = x[min(int(np.searchsorted(s, s[i] + half_arc)), len(x) - 1)]
    p, q = x[i] - a, b - a
    return float(np.linalg.norm(p) * np.linalg.norm(b - x[i]) * np.linalg.norm(q) / (2.0 * np.linalg.norm(np.cross(p, q))))


def contact_runs(x, D, reach=1.0, skip=3.0):
    """The contact set of the polyline x (N, 3) of a rod of diameter D, as runs of consecutive
    nodes whose nearest node more than ``skip`` D away along the rod is closer than ``reach`` D.
    Returns [(s_start, s_end), ...] in arc length, in order along the rod; a run of length up to
    about D is an isolated contact point, a longer one an interval."""
    x = np.asarray(x, dtype=float)
    check_positive("D", D)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(x, axis=0), axis=1))])
    dist = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=-1)
    dist = np.where(np.abs(s[:, None] - s[None, :]) > skip * D, dist, np.inf)
    touching = np.flatnonzero(dist.min(axis=1) < reach * D)
    if touching.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(touching) > 1)
    starts = np.concatenate([[touching[0]], touching[breaks + 1]])
    ends = np.concatenate([touching[breaks], [touching[-1]]])
    return [(float(s[a]), float(s[b])) for a, b in zip(starts, ends)]
