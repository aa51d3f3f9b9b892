"""A solved loop beside its analytic reference: tangent angles and their distance from NvdHT's
envelope, the root taken among those solved, the rows of a comparison, and the profiles of a loop
turned onto the analytic one."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...validation import check_positive
from .compiled import end_loads
from .helix import localization_parameter, localized_helix, localized_helix_curve, reference_check


def tangent_angles(x, axis=(0.0, 0.0, 1.0)):
    """The angle (M,) of each edge of the polyline x (N, 3) to ``axis``."""
    e = np.diff(np.asarray(x, dtype=float), axis=0)
    e /= np.linalg.norm(e, axis=1)[:, None]
    a = np.asarray(axis, dtype=float)
    return np.arccos(np.clip(e @ (a / np.linalg.norm(a)), -1.0, 1.0))


def envelope_error(x, m, t, L=1.0, axis=(0.0, 0.0, 1.0)):
    """L1 distance over s, integral |theta_h(s) - theta(s)| ds / L, between the tangent angle of
    a clamped rod's nodes x (N, 3) (edge i at s = i h - L/2 from the midpoint, h = L / (N - 2):
    edges 0 and N-2 are the clamps) and the localized helix's theta(s) (``localized_helix_curve``)."""
    localized_helix(m, t, 1.0)  # m finite, t positive, m^2 < 4 t
    L = check_positive("L", L)
    th = tangent_angles(x, axis)
    n_edges = th.size
    h = L / (n_edges - 1)
    s = np.arange(n_edges) * h - 0.5 * L
    lam = localization_parameter(m, t)
    exact = np.arccos(np.clip(1.0 - 2.0 * lam * lam / t / np.cosh(lam * s / L) ** 2, -1.0, 1.0))
    w = np.full(n_edges, h)
    w[[0, -1]] = 0.5 * h  # trapezoidal weights between the clamps
    return float(np.sum(w * np.abs(th - exact)) / L)


def choose_helix_root(candidates, n_found, root):
    """(name, reason) of the loop taken among ``candidates``, (name, t, stable) in the order solved,
    of the ``n_found`` roots, for the choice ``root`` ("stable", "small", "large" or "both"): the
    only one solved or asked for, else the stable one; where none or several are, the larger t."""
    if n_found == 1 or root in ("small", "large") or len(candidates) == 1:
        why = "the only root" if n_found == 1 else f"--root {root}" \
            if root in ("small", "large") else "the only root solved"
        return candidates[0][0], why
    stable = [c for c in candidates if c[2]]
    taken = max(stable or candidates, key=lambda c: c[1])[0]
    why = ("the stable root" if len(stable) == 1 else
           "no root is stable: the larger t" if not stable else "both roots are stable: the larger t")
    return taken, why


def relative_error(value, reference, valid=True):
    """value / reference - 1, or None where the reference does not apply (not valid)."""
    return value / reference - 1.0 if valid else None


def helix_state(scene, eq, R, ref, B, ea):
    """One equilibrium ``eq`` of the ``EndLoadedRod`` ``scene`` (length L = 1) at end rotation R
    (rad) beside the localized helix ``ref`` (or None: no analytic loop): a dict of the end
    loads R, M (moment), T (force), m = ML/B, t = TL^2/B (B the bending stiffness), theta_max
    (rad), Lk, Wr, Tw, Lk_expected = R / 2 pi, the Morse index (morse, stable,
    lowest_eigenvalue), and the analytic m, t, theta_max, Wr, Tw (None without ref) with
    reference_valid (``reference_check`` at ea = EA L^2/B; None without ref)."""
    loads = end_loads(scene, eq.q, R, eq.neighbourhood)
    ok = None if ref is None else reference_check(ref, ea).valid
    return {"R": R, "M": loads.M, "T": loads.T, "m": loads.M / B, "t": loads.T / B,  # L = 1
            "m_analytic": None if ref is None else ref.m, "t_analytic": None if ref is None else ref.t,
            "reference_valid": ok,
            "theta_max": float(tangent_angles(eq.x).max()),
            "theta_max_analytic": None if ref is None else ref.theta_max,
            "Lk": eq.Lk, "Wr": eq.Wr, "Tw": eq.Tw, "Lk_expected": R / (2 * math.pi),
            "Wr_analytic": None if ref is None else ref.Wr, "Tw_analytic": None if ref is None else ref.Tw,
            "morse": eq.stability.n_negative, "stable": bool(eq.stability.stable),
            "lowest_eigenvalue": float(eq.stability.eigenvalues[0])}


def helix_root_row(name, ref, check, state=None, attempted=False, note=None):
    """One root's comparison with its analytic loop ``ref``: a dict of its name, the analytic m, t
    and lambda, whether the reference applies (``check``), and from ``state`` (``helix_state``,
    None where not solved) the computed m, t, their relative errors, morse, stable and converged
    (None where not solved, False where Newton was ``attempted`` and failed, with ``note``)."""
    row = {"root": name, "m_analytic": ref.m, "t_analytic": ref.t, "lambda": ref.lam,
           "reference_valid": check.valid, "reference_reason": check.reason}
    if state is not None:
        row.update(m=state["m"], t=state["t"], m_rel_error=relative_error(state["m"], ref.m, check.valid),
                   t_rel_error=relative_error(state["t"], ref.t, check.valid), morse=state["morse"],
                   stable=state["stable"], converged=True)
    else:
        row.update(m=None, t=None, m_rel_error=None, t_rel_error=None, morse=None, stable=None,
                   converged=False if attempted else None, note=note)
    return row


@dataclass(frozen=True)
class HelixProfiles:
    """A clamped rod's loop beside the localized helix (``helix_profiles``), lengths in units of L:
    s_edge (N-1,) the edges' midpoints from the rod's middle, theta (N-1,) their tangent angles
    to the axis (rad) and theta_analytic (N-1,) the helix's; s_node (N,) the nodes' arc lengths,
    x (N, 3) the nodes turned about the axis onto the helix and r (N, 3) the helix's centreline,
    both shifted so that the first edge's midpoint is at the origin."""

    s_edge: np.ndarray
    theta: np.ndarray
    theta_analytic: np.ndarray
    s_node: np.ndarray
    x: np.ndarray
    r: np.ndarray

    def max_distance(self):
        """The largest distance (units of L) between a node and its analytic counterpart."""
        return float(np.max(np.linalg.norm(self.x - self.r, axis=1)))


def helix_profiles(x, ref, L=1.0):
    """``HelixProfiles`` of the nodes x (N, 3) of a clamped rod of length L along z against the
    localized helix ``ref``, the computed loop turned about the axis onto the analytic one."""
    N = len(x)
    theta = tangent_angles(x)
    h_edge = L / (theta.size - 1)
    s_edge = np.arange(theta.size) * h_edge - 0.5 * L
    theta_exact = np.arccos(np.clip(1.0 - 2.0 * ref.lam ** 2 / ref.t / np.cosh(ref.lam * s_edge / L) ** 2, -1, 1))
    s_node = (np.arange(N) - 0.5) * h_edge - 0.5 * L
    _, _, r = localized_helix_curve(ref.m, ref.t, s_node, L)
    r = r - 0.5 * (r[0] + r[1])
    x = x - 0.5 * (x[0] + x[1])
    ang = math.atan2(float(np.sum(x[:, 0] * r[:, 1] - x[:, 1] * r[:, 0])), float(np.sum(x[:, :2] * r[:, :2])))
    c, s_ = math.cos(ang), math.sin(ang)
    x = np.stack([c * x[:, 0] - s_ * x[:, 1], s_ * x[:, 0] + c * x[:, 1], x[:, 2]], axis=1)
    return HelixProfiles(s_edge=s_edge, theta=theta, theta_analytic=theta_exact, s_node=s_node, x=x, r=r)
