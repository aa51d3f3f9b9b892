"""Eigenvalues predicted across a continuation step: a zero crossed between two stable states.

A stable-only continuation corrects each predicted state with a minimiser. Past a branch point of
a loose knot, the minimiser can land on a stable state beside the branch a small distance away: the
step converges, every eigenvalue is positive at both ends, and the path has left its branch without
a word (the trefoil at D/L = 0.024, N = 61: a step from -11.263 pi to -11.275 pi passed the
symmetric branch's instability at -11.2675 pi, which was then reported 0.015 pi late, where the
state beside it folded).

The test here is first-order perturbation theory of the lowest eigenpairs at the last accepted
state: with v_j its unit eigenvectors (eigenvalues lam_j) and s_j = v_j^T (dH/dphi along the
branch) v_j their derivatives along the branch,

    lam_j(phi + dphi) = lam_j + s_j dphi + O(dphi^2).

A mode predicted to cross zero inside a step (lam_j > 0, lam_j + s_j dphi < 0) is a zero to
locate, even when both ends of the step are stable: the step is refused and the end located as
any other; from a closer state whose prediction no longer crosses, the continuation goes on.

The corrected state is also compared with the prediction (``departure``): its lowest
eigenvalues against the last state's, predicted as a block (degenerate perturbation theory) and
compared in ascending order. A step that fails is retried at half the length, down to an eighth of
the largest step; one that still fails is accepted with a warning, not taken for a branch end.
Measured on the trefoil: taken as an end, with a tolerance of the predicted change, half the
eigenvalue and 50 times the near-zero band, it ended the N = 61 opening branch 0.9 pi early at
step pi: the minimiser corrector lands on another placement of the nodes along the nearly null
slides, whose soft spectrum differs by more than that, even for steps of 3e-4 pi. Matched mode by
mode by eigenvector overlap it failed in 30 of 81 ordinary 0.5 pi steps at N = 61. It also finds
where the corrector steps over a fold by less than D/2 (command 1's third buckled branch, next to a
fold at 13.2218 pi): that is what the warning says.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import jax
import jax.numpy as jnp
import numpy as np

from ..aot import cached_jit
from ..linalg.stability import scene_bilinear_gradient

# Modes checked: the lowest few physical eigenpairs (the ones that go soft first).
CHECKED_MODES = 4

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
    ``tangent`` (dq/dphi, physical DOFs) is the continuation's predictor, which leaves the tracked
    mode's cluster out (it is built for symmetric branches, whose tangent has no component along
    a symmetry-breaking mode); near a fold that component is the one that grows like 1/lam."""
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
    phi and ``block`` (m, m) v_i^T (dH along the branch) v_j are computed when first asked for
    (``scene_bilinear_gradient``: m contractions for the slopes, m (m - 1) / 2 more for the block)."""

    scene: object
    prev: object
    du: np.ndarray = field(repr=False)
    eigenvalues: np.ndarray
    vectors: np.ndarray = field(repr=False)

    def _contraction(self, a, c):
        u = self.scene.to_scaled(np.asarray(self.prev.q, dtype=float))
        gu, gp = scene_bilinear_gradient(self.scene, u, self.prev.phi, self.prev.neighbourhood, a, c, 0.0)
        return float(np.dot(np.asarray(gu), self.du) + float(gp))

    @cached_property
    def slopes(self):
        return np.asarray([self._contraction(v, v) for v in self.vectors.T])

    @cached_property
    def block(self):
        m = self.eigenvalues.size
        block = np.diag(self.slopes)
        for i in range(m):
            for j in range(i + 1, m):
                block[i, j] = block[j, i] = self._contraction(self.vectors[:, i], self.vectors[:, j])
        return block

    def crossing(self, phi, floor, keep=None):
        """The first mode predicted to cross zero between prev.phi and phi, as a ``Crossing``, or
        None: where lam > 0, lam + s dphi < 0 and the predicted change |s dphi| exceeds ``floor``
        (the near-zero band of a loose knot's sliding modes, ``negative_tol``: a change inside it
        is not resolved). keep: a function (n, k) vectors -> (k,) bools, the modes that may count
        (a knot's slides are left out by the caller)."""
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
        model's predicted to its twist: the eigenvalues of diag(lam) + dphi block (degenerate
        perturbation theory: a near-degenerate pair of a three-fold knot turns inside its plane
        from step to step, so its members are predicted together, not one by one), compared in
        ascending order (no eigenvector matching is needed), all but the highest (an eigenvalue may
        come down from above it), each allowed |predicted - lam| + DEPARTURE_RELATIVE |predicted| +
        DEPARTURE_FLOOR floor; None where they agree. The contact energy is C2, so the eigenvalues
        are continuous along a branch: a shorter step meets the tolerance, unless the corrector
        lands on another state."""
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


def branch_model(scene, prev, tangent, floor, modes=CHECKED_MODES):
    """The ``BranchModel`` of the accepted equilibrium ``prev`` (with its stability; ``tangent``
    dq/dphi there, physical DOFs) over its lowest ``modes`` eigenpairs; floor: as in
    ``branch_tangent``."""
    st = prev.stability
    m = min(modes, len(st.eigenvalues))
    return BranchModel(scene, prev, branch_tangent(scene, prev, tangent, floor, modes),
                       np.asarray(st.eigenvalues[:m], dtype=float), np.asarray(st.eigenvectors)[:, :m])


def predicted_crossing(scene, prev, tangent, phi, floor, modes=CHECKED_MODES, keep=None):
    """The first of the lowest ``modes`` eigenpairs of the accepted equilibrium ``prev`` predicted
    to cross zero between prev.phi and phi (``BranchModel.crossing``), or None."""
    return branch_model(scene, prev, tangent, floor, modes).crossing(phi, floor, keep)


# A corrected state's lowest eigenvalues may differ from their prediction by the predicted change
# plus this fraction of the eigenvalue, and by DEPARTURE_FLOOR times the near-zero band, before the
# state counts as another one (``departure``).
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


def departure(scene, prev, tangent, new, floor, modes=CHECKED_MODES):
    """A ``Departure`` where the corrected equilibrium ``new``'s lowest eigenvalues are not the
    accepted equilibrium ``prev``'s predicted along the branch (``BranchModel.departure``), or
    None."""
    return branch_model(scene, prev, tangent, floor, modes).departure(new, floor)
