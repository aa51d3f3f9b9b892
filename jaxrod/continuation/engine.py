"""The one predictor-corrector-accept step that both continuations are loops over
(``ContinuationEngine``), its outcome (``_Step``, refused with a ``StepFailure``), and the choice
between the dense and the O(n) block linear algebra (``uses_sparse``, ``grown_engine``)."""
from __future__ import annotations

import enum
import math
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

import jax.numpy as jnp

from ..solve.equilibrium import (
    Equilibrium, EquilibriumOptions, LeftBranchError, RelaxOptions, TopologyChangeError, mode_step, relax,
    solve_equilibrium,
)
from ..model.geometry import polyline_distance
from ..solve.solvers import ConvergenceError
from ..solve.solvers import HostDampedNewton, minimise
from .sparse_branch import EXTRA_PAIRS, solve_equilibrium_sparse, sparse_branch_analysis
from ..linalg.backend import SPARSE_MIN_DOF, choose_backend
from ..linalg.sparse_contact import deflated_newton_direction
from ..solve.equilibrium import equilibrium_from_solution, scaled_energy
from ..linalg.stability import SLIDING_FRACTION, branch_analysis, sliding_fraction
from .branch_check import branch_model
from ..model.symmetry import ROUND_OFF_ASYMMETRY, SYMMETRIC_TOL, joint_two_fold, symmetrize, two_fold_asymmetry
from .options import ContinuationOptions, Task


class StepFailure(enum.Enum):
    """Why a continuation step was refused (never parsed from a message)."""

    NOT_CONVERGED = "not converged"  # the corrector failed (ConvergenceError)
    TOPOLOGY = "topology"  # the rod passed through itself
    JUMP = "jump"  # the state left the branch (moved more than jump_tol from the prediction)
    LINKING = "linking"  # Lk is not Lk0 + phi/2pi
    UNSTABLE = "unstable"  # converged on the branch, but with a negative eigenvalue


@dataclass(frozen=True)
class _Refusal:
    failure: StepFailure
    detail: str
    modes: np.ndarray | None = field(default=None, compare=False, repr=False)  # (n, m): the critical modes
    predicted: bool = False  # refused on a prediction (a zero predicted inside the step), not a measurement

    def __str__(self):
        return f"{self.failure.value}: {self.detail}"


# A follow_twist corrector out of steps with a gradient within this factor of gtol has stalled on
# sliding modes: Newton finishes it (``ContinuationEngine._finish_stalled``).
STALL_FACTOR = 100.0

@dataclass(frozen=True)
class _Step:
    """The outcome of one step: equilibrium (None if the corrector failed); tangent: dq/dphi there;
    eigenvalue, dlambda_dphi, mode: the tracked eigenpair; refusal: why refused (None: accepted)."""

    equilibrium: Equilibrium | None
    tangent: np.ndarray | None = field(default=None, repr=False)
    eigenvalue: float = math.nan
    dlambda_dphi: float = math.nan
    mode: np.ndarray | None = field(default=None, repr=False)
    refusal: _Refusal | None = None
    departure: object = None  # a ``branch_check.Departure`` of an accepted minimiser step, or None

    @property
    def ok(self):
        return self.refusal is None


@dataclass(frozen=True)
class ContinuationEngine:
    """The one predictor-corrector-accept step that both continuations are loops over: predictor,
    the branch tangent; corrector: Newton for ``critical_twist`` (it must also converge
    past the crossing, onto the branch just turned unstable), the guided damped-Newton minimiser
    of ``relax`` for ``follow_twist``. Analysis: stability, the tracked eigenpair with its
    derivative along the branch, the new tangent. Acceptance: any converged state for
    ``critical_twist``; for ``follow_twist`` one within jump_tol of the prediction, with
    Lk = Lk0 + phi/2pi (closed rods) and no negative eigenvalue."""

    scene: object
    task: Task
    opts: ContinuationOptions
    sparse: bool = False

    @property
    def contact(self):
        return self.scene.has_term("contact")

    @property
    def closed(self):
        return bool(self.scene.closed)

    @property
    def lk0(self):
        return float(getattr(self.scene, "Lk0", 0.0))

    @property
    def pinv_tol(self):
        # Near-zero sliding modes of a contact knot are left out of the tangent's pseudo-inverse.
        return self.opts.negative_tol if self.contact else 0.0

    def analyse(self, e, index=0, ref=None, guess=None):
        """(stability, eigenvalue, dlambda_dphi, mode, tangent) at the equilibrium e: the eigenpair
        tracked is number ``index``, or the one nearest ``ref`` (an eigenvector)."""
        analysis = sparse_branch_analysis if self.sparse else branch_analysis
        return analysis(self.scene, e.q, e.phi, index, k=self.opts.k, tol=self.opts.negative_tol, ref=ref,
                        pinv_tol=self.pinv_tol, nbr=e.neighbourhood, guess=guess)

    def analysed(self, e, index=0, ref=None, guess=None):
        """``analyse`` as a _Step: the equilibrium with its stability attached."""
        stab, lam, dlam, v, dq = self.analyse(e, index, ref, guess)
        return _Step(replace(e, stability=stab), dq, lam, dlam, v)

    def step(self, prev, tangent, phi, index=0, ref=None, guess=None):
        """Predict from ``prev`` (an Equilibrium) along ``tangent`` to ``phi``, correct, analyse and
        accept or refuse (index, ref, guess: see ``analyse``). -> _Step."""
        q_pred = prev.q + tangent * (phi - prev.phi)
        if self.task is Task.CRITICAL_TWIST:
            return self._newton_step(prev, q_pred, phi, index, ref, guess)
        return self._minimiser_step(prev, tangent, q_pred, phi)

    @property
    def linear_algebra(self):
        return "sparse" if self.sparse else "dense"

    @property
    def corrector_options(self):
        """The minimiser corrector's ``RelaxOptions`` (no stability: the engine analyses it)."""
        return RelaxOptions(gtol=self.opts.gtol, max_steps=self.opts.corrector_max_steps, with_stability=False,
                            linear_algebra=self.linear_algebra)

    def _newton(self, phi, q_start, nbr):
        if self.sparse and self.contact:
            return self._deflated_newton(phi, q_start, nbr)
        if self.sparse:
            return solve_equilibrium_sparse(self.scene, phi, q_start, gtol=self.opts.gtol, nbr=nbr)
        newton = EquilibriumOptions(method="newton", gtol=self.opts.gtol, with_stability=False,
                                    near_null_tol=self.opts.negative_tol if self.contact else 0.0)
        return solve_equilibrium(self.scene, phi, q_start, newton, nbr=nbr)

    def _deflated_newton(self, phi, q_start, nbr):
        """Newton at O(n) with the near-null sliding modes deflated, within nbr (checked to hold at
        the result, else ConvergenceError)."""
        scene = self.scene
        solver = HostDampedNewton(direction=_DeflatedDirection(self.opts.negative_tol), max_backtracks=40)
        args = (scene, jnp.asarray(phi), nbr)
        sol = minimise(scaled_energy, scene.to_scaled(np.asarray(q_start, dtype=float)), args, solver,
                       self.opts.gtol, 50, throw=False)
        q = scene.from_scaled(np.asarray(sol.y))
        upd = nbr.update(scene, q, phi)
        if not sol.converged or upd.drifted or bool(nbr.stale(scene.positions(np.asarray(q, dtype=float)))):
            raise ConvergenceError(f"deflated Newton did not converge: {sol!r}")
        return equilibrium_from_solution(scene, phi, sol, upd.nbr, with_stability=False)

    def _newton_step(self, prev, q_pred, phi, index, ref, guess):
        try:
            e = self._newton(phi, q_pred, prev.neighbourhood)
        except ConvergenceError:
            try:  # from the last state itself, in case the predictor overshot
                e = self._newton(phi, prev.q, prev.neighbourhood)
            except ConvergenceError as exc:
                return _Step(None, refusal=_Refusal(StepFailure.NOT_CONVERGED, str(exc)))
        return self.analysed(e, index, ref, guess)

    def _minimiser_step(self, prev, tangent, q_pred, phi):
        opts = self.opts
        x_pred = np.asarray(self.scene.positions(jnp.asarray(q_pred)))
        try:
            e = relax(self.scene, phi, q_pred, self.corrector_options, previous=prev, nbr=prev.neighbourhood,
                      guide=(x_pred, opts.jump_tol))
        except LeftBranchError as exc:
            return _Step(None, refusal=_Refusal(StepFailure.JUMP, str(exc)))
        except TopologyChangeError as exc:
            return _Step(None, refusal=_Refusal(StepFailure.TOPOLOGY, str(exc)))
        except ConvergenceError as exc:
            e = self._finish_stalled(exc, phi, prev)
            if e is None:
                return _Step(None, refusal=_Refusal(StepFailure.NOT_CONVERGED, str(exc)))
        e = self.kept_symmetric(prev.q, e, phi, previous=prev)
        moved = polyline_distance(e.x, x_pred, self.closed)
        if moved > opts.jump_tol:
            return _Step(e, refusal=_Refusal(StepFailure.JUMP, f"the state moved {moved:.3g} from the predicted shape"))
        s = self.analysed(e)
        if self.closed and abs(s.equilibrium.Lk - (self.lk0 + phi / (2.0 * math.pi))) > 1e-6:
            return replace(s, tangent=None,
                           refusal=_Refusal(StepFailure.LINKING, f"Lk = {s.equilibrium.Lk:.8f} is not Lk0 + phi/2pi"))
        if s.equilibrium.stability.n_negative > 0 and self.contact:
            # A loose knot's sliding mode may turn slightly negative (a saddle of the slide): push
            # along it and relax; a stable state of the same shape continues the branch.
            escaped = self._escape_soft_saddle(s.equilibrium, prev, x_pred)
            if escaped is not None:
                s = escaped
        n_negative = s.equilibrium.stability.n_negative
        if n_negative > 0:
            return replace(s, refusal=_Refusal(StepFailure.UNSTABLE, f"{n_negative} negative eigenvalue(s)"))
        model = self.branch_model(prev, tangent)
        if model is None:
            return s
        crossing = model.crossing(phi, self.opts.negative_tol, self._shape_modes(prev))
        if crossing is not None:
            # stable at both ends, but a mode is predicted to cross zero in between: locate it
            return replace(s, refusal=_Refusal(StepFailure.UNSTABLE, crossing.detail(), modes=crossing.mode[:, None],
                                               predicted=True))
        return replace(s, departure=model.departure(s.equilibrium, self.opts.negative_tol))

    def branch_model(self, prev, tangent):
        """prev's ``branch_check.BranchModel`` (its lowest eigenpairs predicted along the branch),
        or None where ``check_branch`` is off or prev has no stability."""
        if not self.opts.check_branch or prev.stability is None:
            return None
        return branch_model(self.scene, prev, tangent, self.opts.negative_tol, sparse=self.sparse)

    def predicted_crossing(self, prev, tangent, phi):
        """The first of prev's lowest shape modes (slides left out) predicted to cross zero between
        prev.phi and phi (``branch_check.Crossing``), or None (also without a ``branch_model``)."""
        model = self.branch_model(prev, tangent)
        return None if model is None else model.crossing(phi, self.opts.negative_tol, self._shape_modes(prev))

    def _shape_modes(self, prev):
        """None, or for a knot with contact the filter that leaves its slides out of a check."""
        if not self.contact:
            return None

        def keep(vectors):
            return sliding_fraction(self.scene, prev.q, vectors) > SLIDING_FRACTION
        return keep

    def kept_symmetric(self, reference_q, e, phi, previous=None):
        """e, or e projected back onto the two-fold symmetry of ``reference_q`` and finished by the
        corrector, where it drifted off it by more than round-off and at most jump_tol
        (``ContinuationOptions.keep_symmetry``); e itself where the corrector fails. previous: the
        last Equilibrium, if any."""
        if not self.opts.keep_symmetry:
            return e
        edge = float(self.scene.length) / self.scene.n_nodes
        if joint_two_fold(self.scene, reference_q, SYMMETRIC_TOL * edge) is None:
            return e
        sym = two_fold_asymmetry(e.x)
        if not ROUND_OFF_ASYMMETRY * edge < sym.asymmetry <= self.opts.jump_tol:
            return e
        try:
            # the corrector itself (it stops at once or after one step; no other program to compile)
            return relax(self.scene, phi, symmetrize(self.scene, e.q, sym), self.corrector_options,
                         previous=previous, nbr=e.neighbourhood)
        except (ConvergenceError, LeftBranchError, TopologyChangeError) as exc:
            # not silently: the rest of the branch may then be followed off the symmetry
            warnings.warn(f"phi = {phi / math.pi:+.5f} pi: the state drifted {sym.asymmetry:.2g} off the two-fold "
                          f"symmetry through the joint and could not be brought back ({exc}); kept as corrected",
                          stacklevel=2)
            return e

    def _finish_stalled(self, exc, phi, prev):
        """A contact knot's minimiser out of steps within STALL_FACTOR of gtol (stalled on the
        near-null slides, not at a fold), finished with Newton; None if that fails too."""
        sol = getattr(exc, "solution", None)
        if not self.contact or sol is None or exc.q is None or not sol.grad_norm < STALL_FACTOR * self.opts.gtol:
            return None
        try:
            return self._newton(phi, exc.q, prev.neighbourhood)
        except ConvergenceError:
            return None

    def _escape_soft_saddle(self, e, prev, x_pred):
        """From a saddle e, relax after pushes of +-jump_tol/4 along its most negative mode; the
        analysed _Step of a stable state within jump_tol of the predicted shape x_pred, or None."""
        jump_tol = self.opts.jump_tol
        v = np.asarray(e.stability.eigenvectors[:, 0])
        step = mode_step(self.scene, v, 0.25 * jump_tol)
        for sgn in (1.0, -1.0):
            try:
                # guided: a push along a real buckling mode is stopped at its first pause
                e2 = relax(self.scene, e.phi, e.q + sgn * step, self.corrector_options, previous=prev,
                           nbr=e.neighbourhood, guide=(x_pred, jump_tol))
            except (ConvergenceError, TopologyChangeError):
                continue
            if polyline_distance(e2.x, x_pred, self.closed) > jump_tol:
                continue
            s = self.analysed(e2)
            if s.equilibrium.stability.n_negative == 0:
                return s
        return None


# "auto" takes the O(n) block path from this many DOFs on.
_SPARSE_MIN_DOF = SPARSE_MIN_DOF


def uses_sparse(scene, linear_algebra):
    """Whether a continuation uses the O(n) path (``ContinuationOptions.linear_algebra``)."""
    return choose_backend(scene, linear_algebra).backend.structured


@dataclass(frozen=True)
class _DeflatedDirection:
    """``sparse_contact.deflated_newton_direction`` with its tolerance bound (hashable: jitted pieces
    keyed on it are shared)."""

    near_null_tol: float

    def __call__(self, y, args, g, mu_prev):
        return deflated_newton_direction(y, args, g, mu_prev, self.near_null_tol)


K_MARGIN = EXTRA_PAIRS  # eigenpairs beyond the tracked index or the negative count (sparse path)


def grown_engine(engine, needed):
    """``engine``, or on the sparse path a copy with k = needed + K_MARGIN where its k is less
    (needed: the tracked index or the negative count)."""
    k = needed + K_MARGIN
    if not engine.sparse or k <= engine.opts.k or engine.opts.k >= engine.scene.n_dof:
        return engine
    return replace(engine, opts=replace(engine.opts, k=min(k, int(engine.scene.n_dof))))

