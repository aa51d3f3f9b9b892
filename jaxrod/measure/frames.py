"""The material frame of a measured rod and its profiles: tangent and curvature vector by
second-order differences on the equal-arc-length grid, d1 towards the paired eccentric point,
kappa1, kappa2, tau, and the turning angles of d1 carried along the resampled polygon (steps 4-6
of ``jaxrod.measure.analysis.analyze``)."""
from __future__ import annotations

import numpy as np

from ..model.geometry import parallel_transport, signed_angle
from .pairing import expected_parameters, pair, pairing_jumps


def unit(v):
    """v (..., 3) normalised along its last axis."""
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _transport(v, t_from, t_to):
    return np.asarray(parallel_transport(v, t_from, t_to))


def turning_angles(d_from, t_from, d_to, t_to):
    """Signed angles (about t_to) from transported d_from to d_to. All (M,3) -> (M,)."""
    return np.asarray(signed_angle(_transport(d_from, t_from, t_to), d_to, t_to))


def tangent_and_curvature(x, h, closed):
    """(d3 (N, 3) unit tangents by central differences, x'' (N, 3) by the compact second
    difference) at the nodes x (N, 3) spaced h in arc length; closed curves periodic, open ones
    with second-order one-sided stencils at the ends."""
    if closed:
        xp, xm = np.roll(x, -1, axis=0), np.roll(x, 1, axis=0)
        return unit(xp - xm), (xp - 2.0 * x + xm) / h**2
    d3 = unit(np.gradient(x, h, axis=0, edge_order=2))
    xss = np.empty_like(x)
    xss[1:-1] = (x[2:] - 2.0 * x[1:-1] + x[:-2]) / h**2
    xss[0] = (2.0 * x[0] - 5.0 * x[1] + 4.0 * x[2] - x[3]) / h**2
    xss[-1] = (2.0 * x[-1] - 5.0 * x[-2] + 4.0 * x[-3] - x[-4]) / h**2
    return d3, xss


def paired_frame(x, d3, curve, T, closed, n_dense, L):
    """The eccentric point paired with each node x (N, 3) of tangent d3 (``pair``; paired again by
    continuity where the pairing jumps along the line) and the frame it sets: (points (N, 3), their
    parameters on ``curve`` (N,), crossed (N,) bool, the offsets' distances r (N,) from the
    centreline in the normal planes, d1 (N, 3), d2 (N, 3)). Raises ValueError where the line lies
    on the centreline (an offset below 1e-9 of the length L)."""
    ecc, e_t, crossed = pair(x, d3, curve, T, closed, n_dense)
    offset = np.linalg.norm(ecc - x, axis=-1)
    jumps = pairing_jumps(e_t, T, closed) & crossed
    if np.any(jumps) and np.sum(crossed) >= 4:
        # Where strands touch, a node's normal plane may meet another strand's line as near as
        # its own: pair again by continuity, each node with the crossing nearest the parameter
        # interpolated from the nodes whose pairing advanced smoothly.
        expected = expected_parameters(e_t, crossed, T, closed)
        ecc, e_t, crossed = pair(x, d3, curve, T, closed, n_dense, expected=expected,
                                 reach=2.0 * float(np.median(offset)))
    w = ecc - x
    w = w - np.sum(w * d3, axis=-1, keepdims=True) * d3
    r = np.linalg.norm(w, axis=-1)
    if np.min(r) <= 1e-9 * L:
        i = int(np.argmin(r))
        raise ValueError(
            f"eccentric: the eccentric line lies on the centreline (offset {r[i]:.3g} at node {i}, "
            f"length {L:.6g}); it must be a line drawn at a distance from the centreline"
        )
    d1 = w / r[:, None]
    return ecc, e_t, crossed, r, d1, np.cross(d3, d1)


def curvature_and_twist(xss, d1, d2, h, closed):
    """(kappa1 = -d2.x'', kappa2 = d1.x'', tau = d1'.d2) at the nodes, d1' by central differences
    (closed: periodic; open: second order at the ends)."""
    kappa1 = -np.sum(xss * d2, axis=-1)
    kappa2 = np.sum(xss * d1, axis=-1)
    if closed:
        d1s = (np.roll(d1, -1, axis=0) - np.roll(d1, 1, axis=0)) / (2.0 * h)
    else:
        d1s = np.gradient(d1, h, axis=0, edge_order=2)
    return kappa1, kappa2, np.sum(d1s * d2, axis=-1)


def frame_turning_angles(x, d1, d3, closed):
    """The signed angles (right-hand rule about the tangent) between d1 and its parallel transport
    from the previous frame, along the frames carried from the nodes to the edges of the polygon x
    (averaged, projected normal to each edge): closed, round the edges; open, node 0, edges
    0 ... N-2, node N-1. Their sum over 2 pi is the twist Tw."""
    if closed:
        te = unit(np.roll(x, -1, axis=0) - x)  # edge i: x_i -> x_{i+1}
        d3n, d1n = np.roll(d3, -1, axis=0), np.roll(d1, -1, axis=0)
    else:
        te = unit(x[1:] - x[:-1])
        d3n, d1n = d3[1:], d1[1:]
    de = _transport(d1[: te.shape[0]], d3[: te.shape[0]], te) + _transport(d1n, d3n, te)
    de = unit(de - np.sum(de * te, axis=-1, keepdims=True) * te)
    if closed:
        return turning_angles(np.roll(de, 1, axis=0), np.roll(te, 1, axis=0), de, te)
    t_seq = np.concatenate([d3[:1], te, d3[-1:]], axis=0)
    d_seq = np.concatenate([d1[:1], de, d1[-1:]], axis=0)
    return turning_angles(d_seq[:-1], t_seq[:-1], d_seq[1:], t_seq[1:])
