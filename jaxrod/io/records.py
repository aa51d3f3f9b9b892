"""What is recorded of each equilibrium along a twist continuation: the seed paper's observables.

``step_record(scene, eq)`` returns a flat row (a dict of numbers, one CSV row) and the profiles
(curvature kappa(s) and twist density tau(s), as the paper's simulation computes them from
neighbouring frames, see ``vertex_profiles``; measured shapes go through ``jaxrod.measure.analysis``
instead), plus the centreline and eccentric line for 3D snapshots.

Lk is reported twice, independently: from the frames (Wr + Tw of the discrete rod, exact polygon
writhe) and from the Gauss linking integral of the centreline with the eccentric line (exact
polygon linking number), the paper's estimate, which does not use the frame twist at all. The
latter only at whole turns: the rod's ends were turned by phi before gluing, so unless phi is a
whole number of turns the eccentric line jumps at the joint, does not close, and its Gauss
integral is not defined (``Lk_gauss`` is NaN there, an empty cell in branch.csv).
"""
from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..aot import cached_jit
from ..measure.profiles import count_peaks, symmetry_order
from ..model.geometry import radius_of_gyration
from ..model.topology import is_whole_turns, linking_number

__all__ = ["step_record", "vertex_profiles", "ROW_KEYS", "ROW_UNITS"]

# Columns of a continuation table (branch.csv) before the eigenvalue columns lambda_0 ...
ROW_KEYS = (
    "branch", "phi", "phi_over_pi", "energy", "E_stretch", "E_bend", "E_twist", "E_contact",
    "Wr", "Tw", "Lk_frames", "Lk_gauss", "Lk_expected", "n_negative", "stable", "contact_count",
    "symmetry_order", "n_peaks", "kappa_max_L", "tau_mean_L", "tau_spread_L", "radius_of_gyration",
    "min_distance_over_D", "grad_norm", "iterations",
)


# Units of the columns: lengths in the unit of the scene's D and L (the CLI: mm), energies in
# E x length^3 (with E in MPa = N/mm^2 and lengths in mm: N mm = mJ); eigenvalues and the
# gradient norm in the solvers' scaled units (energy B/l, lengths l: the mean edge length).
ROW_UNITS = {
    "branch": "name", "phi": "rad", "phi_over_pi": "rad/pi", "energy": "E length^3 (N mm with MPa, mm)",
    "E_stretch": "E length^3", "E_bend": "E length^3", "E_twist": "E length^3", "E_contact": "E length^3",
    "Wr": "turns", "Tw": "turns", "Lk_frames": "turns", "Lk_gauss": "turns", "Lk_expected": "turns",
    "n_negative": "count", "stable": "bool", "contact_count": "segment pairs", "symmetry_order": "1",
    "n_peaks": "count", "kappa_max_L": "1 (curvature x L)", "tau_mean_L": "rad (twist density x L)",
    "tau_spread_L": "rad", "radius_of_gyration": "length", "min_distance_over_D": "1", "grad_norm":
    "B/l per l (scaled)", "iterations": "count", "direction": "plus | minus",
    "branch_id": "integer (one per branch; the branch through phi = 0 is 0)",
    "arclength": "along the branch from its first state: sum of sqrt(dphi^2 + |du|^2), u the scaled DOFs "
                 "(node coordinates in mean edge lengths, twist angles in rad); negative on the minus side of "
                 "the branch through phi = 0; from the located end on an unstable branch",
    "morse_index": "count (negative eigenvalues, zero modes excluded; on unstable branches shape modes only)",
    "lambda_j": "B/l (scaled Hessian eigenvalue, zero modes removed)",
}


def _min_nonlocal_distance(x, D):
    """Smallest distance between nodes more than pi D / 2 apart along a closed rod (a cheap
    closest-approach indicator; the contact energy itself uses segment quadrature)."""
    n = x.shape[0]
    seg = np.linalg.norm(np.roll(x, -1, axis=0) - x, axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)[:-1]])
    total = float(np.sum(seg))
    ds = np.abs(s[:, None] - s[None, :])
    ds = np.minimum(ds, total - ds)
    d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=-1)
    d[ds <= 0.5 * math.pi * D] = np.inf
    return float(np.min(d)) if n > 1 else math.inf


def vertex_profiles(scene, eq):
    """Curvature and twist density at the vertices of a closed rod, as the paper's simulation
    gets them from neighbouring bead frames: kappa_i = |kappa b_i| / l_i (|kappa b| = 2 tan(a/2),
    a the turning angle) and tau_i = m_i / l_i (m_i the twist across vertex i, the imposed twist
    included; l_i the Voronoi length). Returns (s/L (N,), kappa L (N,), tau L (N,)).

    The frames themselves are not used: the imposed twist enters at the joint, so unless phi is
    a whole number of turns a line drawn on the rod does not close there (the rod's ends were
    rotated by phi before gluing), and a profile read from the eccentric line would show the
    mismatch as a spike at the joint.
    """
    nbr = eq.neighbourhood if eq.neighbourhood is not None else scene.neighbourhood(eq.q, eq.phi)
    s, kappa, tau = _profiles(scene, jnp.asarray(eq.q), jnp.asarray(eq.phi), nbr)
    return np.asarray(s), np.asarray(kappa), np.asarray(tau)


@cached_jit
def _profiles(scene, q, phi, nbr):
    from ..model.geometry import curvature_binormals, edges

    x = scene.positions(q)
    e = edges(x, True)
    kb = curvature_binormals(jnp.roll(e, 1, axis=0), e)
    lengths = jnp.linalg.norm(e, axis=1)
    vor = 0.5 * (lengths + jnp.roll(lengths, 1))
    m = scene.vertex_twists(q, phi, nbr)
    L = jnp.sum(lengths)
    s = jnp.concatenate([jnp.zeros(1), jnp.cumsum(lengths)[:-1]])
    return s / L, jnp.linalg.norm(kb, axis=1) / vor * L, m / vor * L


@cached_jit
def _record_arrays(scene, q, phi, nbr):
    """Everything a record needs from JAX in one compiled call: eccentric line (N,3), profiles,
    contact count, Gauss linking number of centreline and eccentric line."""
    from ..model.contact import contact_count

    x = scene.positions(q)
    ecc = scene.eccentric_line(q, phi, nbr=nbr)
    s, kappa_L, tau_L = _profiles(scene, q, phi, nbr)
    if scene.has_term("contact"):
        n_contact = contact_count(x, nbr.pairs, nbr.mask, True, scene.material.D)
    else:
        n_contact = jnp.asarray(0)
    return ecc, s, kappa_L, tau_L, n_contact, linking_number(x, ecc)


def step_record(scene, eq, branch="", n_samples=None):
    """Row and profiles of an equilibrium ``eq`` (with its stability) of a closed ``scene``.

    Returns (row, extra): row is a dict with the keys ``ROW_KEYS`` plus ``lambda_j`` for the
    lowest eigenvalues (zero modes removed); extra holds arrays: ``s_over_L`` (n,),
    ``kappa_L`` (n,), ``tau_L`` (n,) (curvature and twist density times L, the paper's frames),
    ``x`` (N,3) centreline, ``eccentric`` (N,3) the line at D/2 along d1.

    ``Lk_gauss`` (the linking number of ``x`` and ``eccentric``) is NaN unless phi is a whole
    number of turns (within 1e-9 turn): otherwise the line does not close at the joint.
    """
    x = np.asarray(eq.x)
    nbr = eq.neighbourhood if eq.neighbourhood is not None else scene.neighbourhood(eq.q, eq.phi)
    ecc, s_over_L, kappa_L, tau_L, n_contact, lk_gauss = jax.device_get(
        _record_arrays(scene, jnp.asarray(eq.q), jnp.asarray(eq.phi), nbr))
    D = None if scene.material.D is None else float(scene.material.D)
    kappa_nodes = kappa_L / float(scene.length)
    terms = eq.energy_terms
    stab = eq.stability
    n_contact = int(n_contact)
    if not is_whole_turns(eq.phi):
        lk_gauss = math.nan  # the line jumps by phi mod 2 pi at the joint: not a closed curve
    row = {
        "branch": branch,
        "phi": float(eq.phi),
        "phi_over_pi": float(eq.phi) / math.pi,
        "energy": float(eq.energy),
        "E_stretch": float(terms.get("stretch", 0.0)),
        "E_bend": float(terms.get("bend", 0.0)),
        "E_twist": float(terms.get("twist", 0.0)),
        "E_contact": float(terms.get("contact", 0.0)),
        "Wr": float(eq.Wr),
        "Tw": float(eq.Tw),
        "Lk_frames": float(eq.Lk),
        "Lk_gauss": float(lk_gauss),
        "Lk_expected": float(scene.Lk0) + float(eq.phi) / (2.0 * math.pi),
        "n_negative": int(stab.n_negative) if stab is not None else -1,
        "stable": int(bool(stab.stable)) if stab is not None else -1,
        "contact_count": n_contact,
        "symmetry_order": int(symmetry_order(kappa_nodes)),
        "n_peaks": int(count_peaks(kappa_nodes)),
        "kappa_max_L": float(np.max(kappa_L)),
        "tau_mean_L": float(np.mean(tau_L)),
        "tau_spread_L": float(np.max(tau_L) - np.min(tau_L)),
        "radius_of_gyration": radius_of_gyration(x),
        "min_distance_over_D": _min_nonlocal_distance(x, D) / D if D else math.nan,
        "grad_norm": float(eq.solution.grad_norm),
        "iterations": int(eq.solution.iterations),
    }
    if stab is not None:
        for j, lam in enumerate(np.asarray(stab.eigenvalues)):
            row[f"lambda_{j}"] = float(lam)
    extra = {
        "s_over_L": s_over_L,
        "kappa_L": kappa_L,
        "tau_L": tau_L,
        "x": x,
        "eccentric": ecc,
    }
    return row, extra
