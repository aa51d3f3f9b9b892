"""Eigenvalues predicted across a continuation step: a zero crossed between two stable states.

Past a branch point of a loose knot the minimiser can land on a stable state beside the branch. So
the last state's lowest eigenvalues are predicted to first order, lam_j + s_j dphi with
s_j = v_j^T (dH/dphi along the branch) v_j, and a mode predicted to cross zero inside a step is a
zero to locate. The corrected spectrum is also checked against the prediction (``departure``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import jax
import jax.numpy as jnp
import numpy as np

from ..aot import cached_jit
from ..linalg.sparse_contact import hessian_times_vectors
from ..linalg.stability import scene_linearisation

# Modes checked: the lowest few physical eigenpairs (the ones that go soft first).
CHECKED_MODES = 4
# The step (rad of twist, scaled DOFs along the tangent) of the central difference of the Hessian
# along the branch.
ALONG_STEP = 1e-5

@dataclass(frozen=True)
class Crossing:
    """A mode of the last accepted state predicted to cross zero inside a step.

    index: its position among the state's eigenpairs; eigenvalue, slope: lam and d lam / d phi
    there; phi: the twist of the linear prediction's zero; mode: (n,) its eigenvector (scaled
    DOFs)."""

    index: int
    eigenvalue: float
    slope: float
    phi: float
    mode: np.ndarray

    def detail(self):
        """One line for a refused step's message."""
        return (f"mode {self.index}'s eigenvalue {self.eigenvalue:.3e} (d/dphi {self.slope:.3e}) is predicted to "
                f"cross zero at phi = {self.phi / math.pi:+.6f} pi, inside the step")


@cached_jit
def _gradient_phi_derivative(scene, u, phi, nbr):
    return jax.jvp(lambda p: jax.grad(scene.scaled_energy)(u, p, nbr), (phi,), (jnp.ones_like(phi),))[1]


def branch_tangent(scene, e, tangent, floor, modes=CHECKED_MODES):
    """(n,) the scaled branch tangent du/dphi at the equilibrium e with its components along e's
    lowest ``modes`` eigenvectors restored: -(v . g_phi) / lam for each of them above ``floor``.
    ``tangent`` (dq/dphi, physical DOFs), the continuation's predictor, leaves those out."""
    u = scene.to_scaled(np.asarray(e.q, dtype=float))
    du = scene.to_scaled(np.asarray(tangent, dtype=float))
    st = e.stability
    m = min(modes, len(st.eigenvalues))
    lam = np.asarray(st.eigenvalues[:m], dtype=float)
    vec = np.asarray(st.eigenvectors)[:, :m]
    g_phi = np.asarray(_gradient_phi_derivative(scene, u, jnp.asarray(float(e.phi)), e.neighbourhood))
    for j in np.nonzero(lam > floor)[0]:
        v = vec[:, j]
        du = du + v * (-(v @ g_phi) / lam[j] - v @ du)
    return du


@dataclass(frozen=True)
class BranchModel:
    """The lowest eigenpairs of an accepted equilibrium and their first-order change along the
    branch: one model per step, shared by the crossing and the departure tests.

    prev: the equilibrium (with its stability); du: (n,) its scaled branch tangent
    (``branch_tangent``); eigenvalues: (m,); vectors: (n, m) scaled DOFs. ``slopes`` (m,) d lam / d
    phi and ``block`` (m, m) v_i^T (dH along the branch) v_j are computed when first asked for."""

    scene: object
    prev: object
    du: np.ndarray = field(repr=False)
    eigenvalues: np.ndarray
    vectors: np.ndarray = field(repr=False)
    sparse: bool = False

    @cached_property
    def block(self):
        # dH by a central difference of the exact Hessian along (du, 1): two Hessians, where the
        # block by autodiff takes m (m + 1) / 2 third-derivative contractions. Its relative error,
        # ~(ALONG_STEP |du|)^2, lies far below the first-order model's own. The Hessians come from
        # the analysis's own compiled program (no other program to compile for this).
        u = self.scene.to_scaled(np.asarray(self.prev.q, dtype=float))
        h = ALONG_STEP / max(1.0, float(np.max(np.abs(self.du))))
        ends = [self._hessian_times_vectors(u + s * h * self.du, self.prev.phi + s * h) for s in (1.0, -1.0)]
        block = self.vectors.T @ (ends[0] - ends[1]) / (2.0 * h)
        return 0.5 * (block + block.T)

    def _hessian_times_vectors(self, u, phi):
        """H(u, phi) @ vectors, (n, m): on the sparse path by products with the O(N) Hessian's
        parts (the dense n x n one grows as N^2, 118 MB at N = 961), else from the dense analysis's
        Hessian."""
        nbr = self.prev.neighbourhood
        if self.sparse:
            return hessian_times_vectors(self.scene, u, float(phi), nbr, self.vectors)
        return np.asarray(scene_linearisation(self.scene, u, phi, nbr)[1]) @ self.vectors

    @cached_property
    def slopes(self):
        return np.diag(self.block).copy()

    def crossing(self, phi, floor, keep=None):
        """The first mode predicted to cross zero between prev.phi and phi, as a ``Crossing``, or
        None: where lam > 0, lam + s dphi < 0 and |s dphi| exceeds ``floor`` (the near-zero band).
        keep: a function (n, k) vectors -> (k,) bools, the modes that may count."""
        lam, vec = self.eigenvalues, self.vectors
        candidates = np.nonzero(lam > 0.0)[0]
        if not candidates.size:
            return None
        slopes = self.slopes[candidates]
        dphi = float(phi - self.prev.phi)
        linear = lam[candidates] + slopes * dphi
        crossing = (linear < 0.0) & (np.abs(slopes * dphi) > floor)
        if keep is not None and np.any(crossing):
            crossing[crossing] = np.asarray(keep(vec[:, candidates[crossing]]), dtype=bool)
        if not np.any(crossing):
            return None
        zero = np.where(crossing, self.prev.phi - lam[candidates] / np.where(slopes != 0.0, slopes, np.inf), np.inf)
        first = int(np.argmin(np.abs(zero - self.prev.phi)))
        j = int(candidates[first])
        return Crossing(index=j, eigenvalue=float(lam[j]), slope=float(slopes[first]), phi=float(zero[first]),
                        mode=vec[:, j].copy())

    def departure(self, new, floor):
        """A ``Departure`` where the corrected equilibrium ``new``'s lowest eigenvalues are not the
        eigenvalues of diag(lam) + dphi block (predicted together: near-degenerate pairs turn),
        compared in ascending order, all but the highest, each allowed |predicted - lam| +
        DEPARTURE_RELATIVE |predicted| + DEPARTURE_FLOOR floor; None where they agree."""
        m = min(self.eigenvalues.size, len(new.stability.eigenvalues))
        if m < 2:
            return None
        lam = self.eigenvalues[:m]
        predicted = np.linalg.eigvalsh(np.diag(lam) + float(new.phi - self.prev.phi) * self.block[:m, :m])
        measured = np.sort(np.asarray(new.stability.eigenvalues[:m], dtype=float))
        tolerance = np.abs(predicted - lam) + DEPARTURE_RELATIVE * np.abs(predicted) + DEPARTURE_FLOOR * floor
        miss = (np.abs(measured - predicted) - tolerance)[:m - 1]
        if not np.any(miss > 0.0):
            return None
        return Departure(int(np.argmax(miss)), predicted, measured, tolerance)


def branch_model(scene, prev, tangent, floor, modes=CHECKED_MODES, sparse=False):
    """The ``BranchModel`` of the accepted equilibrium ``prev`` (with its stability; ``tangent``
    dq/dphi there, physical DOFs) over its lowest ``modes`` eigenpairs; floor: as in
    ``branch_tangent``; sparse: the continuation's linear algebra is the O(N) one (its Hessians
    are then used too)."""
    st = prev.stability
    m = min(modes, len(st.eigenvalues))
    return BranchModel(scene, prev, branch_tangent(scene, prev, tangent, floor, modes),
                       np.asarray(st.eigenvalues[:m], dtype=float), np.asarray(st.eigenvectors)[:, :m], sparse)


def predicted_crossing(scene, prev, tangent, phi, floor, modes=CHECKED_MODES, keep=None):
    """The first of the lowest ``modes`` eigenpairs of the accepted equilibrium ``prev`` predicted
    to cross zero between prev.phi and phi (``BranchModel.crossing``), or None."""
    return branch_model(scene, prev, tangent, floor, modes).crossing(phi, floor, keep)


# Tolerances of ``BranchModel.departure``.
DEPARTURE_RELATIVE = 0.5
DEPARTURE_FLOOR = 50.0


@dataclass(frozen=True)
class Departure:
    """The corrected state's lowest eigenvalues are not those predicted along the branch.

    index: the position (ascending) of the eigenvalue furthest off; predicted, measured: (m,) the
    predicted and the corrected state's eigenvalues, ascending; tolerance: (m,) what was allowed."""

    index: int
    predicted: np.ndarray
    measured: np.ndarray
    tolerance: np.ndarray

    def detail(self):
        j = self.index
        return (f"eigenvalue {j} is {self.measured[j]:.3e}, predicted {self.predicted[j]:.3e} along the branch "
                f"(more than {self.tolerance[j]:.1e} off)")

