"""Pairing the nodes of a resampled centreline with the points of an eccentric line: the crossing
of each node's normal plane nearest the node, or the nearest by continuity along the line where
another strand's line crosses the plane as near (step 4 of ``jaxrod.measure.analysis.analyze``)."""
from __future__ import annotations

import numpy as np


def pair(x, d3, curve, T, closed, n_dense, expected=None, reach=None):
    """Point of the eccentric ``curve`` paired with each node x (N,3) of unit tangent d3 (N,3):
    the crossing of the normal plane nearest to the node (Newton-refined on the curve), or the
    nearest point of the curve if the plane is not crossed. With ``expected`` ((N,) parameters
    on the curve) and ``reach`` (a distance): among the crossings within reach, the one whose
    parameter is nearest the expected one (continuity along the line, where strands touch and
    another strand's line crosses the plane as near as the node's own). Returns (points (N,3),
    params (N,), crossed (N,) bool)."""
    tf = np.linspace(0.0, T, n_dense + 1)
    pf = curve(tf)
    out_t = np.empty(x.shape[0])
    crossed = np.empty(x.shape[0], dtype=bool)
    chunk = max(1, 500_000 // (3 * n_dense))  # bounds the (chunk, n_dense, 3) temporaries
    for lo in range(0, x.shape[0], chunk):
        xs, ts = x[lo: lo + chunk], d3[lo: lo + chunk]
        f = np.einsum("cfk,ck->cf", pf[None, :, :] - xs[:, None, :], ts)  # signed height above plane
        f0, f1 = f[:, :-1], f[:, 1:]
        crosses = (f0 * f1 <= 0.0) & (f0 != f1)
        alpha = np.where(crosses, f0 / np.where(crosses, f0 - f1, 1.0), 0.0)
        q = pf[None, :-1, :] + alpha[:, :, None] * (pf[None, 1:, :] - pf[None, :-1, :])
        dist = np.where(crosses, np.linalg.norm(q - xs[:, None, :], axis=-1), np.inf)
        j = np.argmin(dist, axis=1)
        rows = np.arange(xs.shape[0])
        if expected is not None:
            t_all = tf[None, :-1] + alpha * (tf[None, 1:] - tf[None, :-1])
            gap = t_all - expected[lo: lo + chunk, None]
            if closed:
                gap = (gap + 0.5 * T) % T - 0.5 * T
            score = np.where(dist <= reach, np.abs(gap), np.inf)
            best = np.argmin(score, axis=1)
            j = np.where(np.isfinite(score[rows, best]), best, j)
        found = np.isfinite(dist[rows, j])
        t = tf[j] + alpha[rows, j] * (tf[j + 1] - tf[j])
        a, b = tf[j], tf[j + 1]
        # Newton on g(t) = (r(t) - x).d3, kept inside the bracketing segment.
        for _ in range(4):
            g = np.sum((curve(t) - xs) * ts, axis=-1)
            dg = np.sum(curve(t, 1) * ts, axis=-1)
            ok = np.abs(dg) > 1e-300
            t = np.clip(np.where(ok, t - g / np.where(ok, dg, 1.0), t), a, b)
        if not np.all(found):
            nearest = np.argmin(np.linalg.norm(pf[None, :, :] - xs[:, None, :], axis=-1), axis=1)
            t = np.where(found, t, tf[nearest])
        out_t[lo: lo + chunk] = t
        crossed[lo: lo + chunk] = found
    return curve(out_t), out_t, crossed


def expected_parameters(e_t, crossed, e_T, closed):
    """(N,) parameters on the eccentric line expected at each node from continuity: the paired
    parameters follow a straight trend in the node index (one period per loop for a closed line,
    in the direction most pairs run) up to the line's speed variations (a few per cent of its
    length); nodes further than e_T/8 from the trend were paired with another piece of the line
    (another strand's, which lies a good fraction of the length away) and are ignored; the
    others are interpolated linearly."""
    n = e_t.shape[0]
    i = np.arange(n)
    step = np.diff(np.concatenate([e_t, e_t[:1]]) if closed else e_t)
    if closed:
        step = (step + 0.5 * e_T) % e_T - 0.5 * e_T
    slope = float(np.median(step[np.abs(step) < 0.25 * e_T]))  # parameter per node, with its sense
    if closed:
        slope = np.sign(slope) * e_T / n  # exactly one period per loop
    base = e_t - slope * i
    if closed:  # circular median of the offsets: the angle of the mean direction, then refined
        angle = 2.0 * np.pi * base / e_T
        centre = np.angle(np.mean(np.exp(1j * angle[crossed])))
        dev = (angle - centre + np.pi) % (2.0 * np.pi) - np.pi
        centre += float(np.median(dev[crossed]))
        dev = ((angle - centre + np.pi) % (2.0 * np.pi) - np.pi) * e_T / (2.0 * np.pi)
    else:
        dev = base - float(np.median(base[crossed]))
    good = crossed & (np.abs(dev) < 0.125 * e_T)
    idx = np.flatnonzero(good)
    if idx.size < 2:
        return e_t
    if not closed:
        return np.interp(i, idx, e_t[idx])
    # The offsets from the trend, unwrapped along the good nodes, interpolated around the loop.
    offsets = np.unwrap(2.0 * np.pi * base[idx] / e_T) * e_T / (2.0 * np.pi)
    periodic = np.interp(i, idx, offsets, period=n)
    return (periodic + slope * i) % e_T


def pairing_jumps(e_t, e_T, closed):
    """Nodes where the paired point's parameter on the eccentric line does not advance like its
    neighbours' (it goes back, or leaps ahead): the node was paired with a piece of the line
    that runs along another strand."""
    step = np.diff(np.concatenate([e_t, e_t[:1]]) if closed else e_t)
    if closed:
        step = (step + 0.5 * e_T) % e_T - 0.5 * e_T  # the closed line's parameter wraps at e_T
    typical = float(np.median(step))
    if typical == 0.0:
        return np.ones(e_t.shape[0], dtype=bool)
    odd = (step * np.sign(typical) <= 0.0) | (np.abs(step) > 4.0 * abs(typical))
    nodes = np.zeros(e_t.shape[0], dtype=bool)
    nodes[: odd.shape[0]] |= odd
    nodes[1: odd.shape[0] + 1 if closed else None] |= odd[: e_t.shape[0] - 1]
    if closed:
        nodes[0] |= odd[-1]
    return nodes
