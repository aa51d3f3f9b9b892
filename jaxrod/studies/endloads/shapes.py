"""Starting states of an end-loaded rod: polylines along prescribed tangents closed onto the far
clamp, NvdHT's loop laid on the rod (``helical_start``), and a state restretched to another
stretch stiffness."""
from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from ...validation import check_finite
from .helix import localized_helix, localized_helix_curve
from .resolution import check_helix_resolution
from .scene import check_scene


def _closed_tangents(theta, psi, span, lengths=None, sweeps=20):
    """Unit tangents (n, 3) near the polar angles theta (n,) and azimuths psi (n,) to the axis z
    such that the edges of ``lengths`` (n,; None: 1) along them sum to (0, 0, span): an open
    polyline that meets the far clamp. Alternately, the polar angles are scaled by one factor (the
    axial span) and the lateral sum is removed, mostly from the edges nearest the axis."""
    from scipy.optimize import brentq  # noqa: PLC0415

    theta, psi = np.asarray(theta, dtype=float), np.asarray(psi, dtype=float)
    ell = np.ones_like(theta) if lengths is None else np.asarray(lengths, dtype=float)
    w = 1.0 / (np.sin(theta) ** 2 + 1e-4)
    w /= np.sum(w)
    for _ in range(sweeps):
        top = math.pi / max(float(np.max(theta)), 1e-300)
        gap = lambda k: float(np.sum(ell * np.cos(np.minimum(k * theta, math.pi)))) - span  # noqa: E731, B023
        g1 = gap(1.0)
        if g1 > 0.0 and gap(top) < 0.0:
            theta = np.minimum(brentq(gap, 1.0, top, xtol=1e-15) * theta, math.pi)
        elif g1 < 0.0:
            theta = brentq(gap, 0.0, 1.0, xtol=1e-15) * theta
        tangent = np.stack([np.sin(theta) * np.cos(psi), np.sin(theta) * np.sin(psi), np.cos(theta)], axis=1)
        lateral = np.sum(ell[:, None] * tangent[:, :2], axis=0)
        if float(np.max(np.abs(lateral))) < 1e-13 * len(theta):
            break
        tangent[:, :2] -= (w / ell)[:, None] * lateral[None, :]
        tangent /= np.linalg.norm(tangent, axis=1)[:, None]
        theta, psi = np.arccos(np.clip(tangent[:, 2], -1.0, 1.0)), np.arctan2(tangent[:, 1], tangent[:, 0])
    return tangent


def _frame(scene):
    """(e1, e2, e3): the near clamp's director, e3 x e1, the clamp axis."""
    e3 = np.asarray(scene.axis, dtype=float)
    e1 = np.asarray(scene.director_start, dtype=float)
    return e1, np.cross(e3, e1), e3


def _interior_from_tangents(scene, theta, psi, lengths=None):
    """The interior nodes (n - 4, 3) of ``scene`` on the polyline from the near clamp's node 1
    whose free edges 1 ... n - 3 have ``lengths`` (in edge lengths h; None: 1) and lie near the
    polar angles theta and azimuths psi in the clamps' frame (``_frame``), closed onto the far
    clamp's node n - 2 (``_closed_tangents``; the roundoff left spread evenly)."""
    n, h = scene.n_nodes, float(scene.length_scale)
    xc = np.asarray(scene.x_clamped)
    start, stop = xc[1], xc[2] + np.asarray(scene.end_offset)
    e1, e2, e3 = _frame(scene)
    ell = np.ones(n - 3) if lengths is None else np.asarray(lengths, dtype=float)
    tangent = _closed_tangents(theta, psi, float(np.dot(stop - start, e3)) / h, ell)
    r = h * np.cumsum(ell[:, None] * tangent, axis=0)  # nodes 2 ... n - 2 from node 1, in the frame
    x = start + r[:, :1] * e1 + r[:, 1:2] * e2 + r[:, 2:3] * e3
    miss = x[-1] - stop
    return x[:-1] - (np.arange(1, n - 3) / (n - 3))[:, None] * miss[None, :]


def restretched(scene, q, ratio):
    """q with every free edge's strain multiplied by ``ratio``, the edges' directions kept but
    re-closed onto the far clamp, the twist angles unchanged: the predictor of a stiffening stage,
    EA -> EA / ratio at nearly the same tension."""
    q = np.asarray(q, dtype=float)
    n = scene.n_nodes
    x = np.asarray(scene.nodes(jnp.asarray(q)))
    e = np.diff(x, axis=0)[1:n - 2]
    ell = np.linalg.norm(e, axis=1)
    rest = np.asarray(scene.rest_lengths)[1:n - 2]
    e1, e2, e3 = _frame(scene)
    tau = e / ell[:, None]
    theta = np.arccos(np.clip(tau @ e3, -1.0, 1.0))
    psi = np.arctan2(tau @ e2, tau @ e1)
    lengths = rest * (1.0 + (ell / rest - 1.0) * ratio) / float(scene.length_scale)
    xi = _interior_from_tangents(scene, theta, psi, lengths)
    return np.concatenate([xi.ravel(), q[3 * (n - 4):]])


def helical_start(scene, m, t, phi):
    """A starting state q for ``scene`` (an ``EndLoadedRod``) near the localized helix (m, t): the
    interior nodes on a polyline of the rest edge length along the analytic tangent (s measured
    from the rod's midpoint, the near clamp's point at s = -L/2), closed onto the far clamp, and
    the twist spread evenly so the far clamp's frame is
    turned by phi (m < 0: the mirror image of the loop with -m, for phi < 0). Refused: N too few
    for the loop (``check_helix_resolution``), m^2 >= 4 t."""
    check_scene(scene)
    phi = check_finite("phi", phi)
    localized_helix(m, t, 1.0)  # m finite, t positive, m^2 < 4 t
    check_helix_resolution(scene.n_nodes, m, t, phi)
    L = float(scene.clamp_length)
    n = scene.n_nodes
    h = L / (n - 2)
    # edges of the rest length h along the analytic tangent at their midpoints s_i = -L/2 + i h
    # (chords of the curve would be short by ~(kappa h)^2 / 24, a strain that dwarfs a stiff rod's loads)
    s_mid = -0.5 * L + h * np.arange(1, n - 2)
    theta_a, psi_a, _ = localized_helix_curve(m, t, s_mid, L)
    xi = _interior_from_tangents(scene, theta_a, psi_a)
    # twist: theta_end = phi + end angle, spread over the edges
    probe = np.concatenate([xi.ravel(), np.zeros(n - 3)])
    x_full = np.asarray(scene.nodes(jnp.asarray(probe)))
    theta_end = float(phi) + float(scene.end_angle(jnp.asarray(x_full)))
    m_edges = n - 1
    theta = theta_end * np.arange(1, m_edges - 1) / (m_edges - 1)
    return np.concatenate([xi.ravel(), theta])
