"""Twist continuation and critical twist.

``critical_twist`` follows an equilibrium branch in phi (tangent predictor, Newton corrector) and
watches the count of negative Hessian eigenvalues over the *whole* spectrum (zero modes removed),
so an unstable mode that comes down from high in the spectrum is caught. When the count changes
between two steps, the crossing eigenvalue (the one with ascending index = the count before) is
driven to zero by Newton's method in phi, using its derivative along the branch from forward-mode
autodiff (``stability.branch_analysis``), safeguarded by the bracket. A handful of
Hessian evaluations reach 1e-10 rad, where bisection would need ~30.
"""
from __future__ import annotations

import enum
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

import jax.numpy as jnp

from .equilibrium import Equilibrium, LeftBranchError, TopologyChangeError, relax, solve_equilibrium
from .geometry import polyline_distance
from .validation import check_finite, check_int_at_least, check_positive
from .solvers import ConvergenceError
from .sparse_branch import solve_equilibrium_sparse, sparse_branch_analysis
from .stability import DEFAULT_NEGATIVE_TOL, branch_analysis

__all__ = ["ContinuationOptions", "Task", "PathStop", "StepFailure", "BranchEnd", "CriticalPoint", "critical_twist", "NoCrossingError", "BranchPoint", "Instability", "TwistPath", "follow_twist"]


class StepFailure(enum.Enum):
    """Why a continuation step was refused (never parsed from a message)."""

    NOT_CONVERGED = "not converged"  # the corrector failed (ConvergenceError)
    TOPOLOGY = "topology"  # the rod passed through itself
    JUMP = "jump"  # the state left the branch (moved more than jump_tol from the prediction)
    LINKING = "linking"  # Lk is not Lk0 + phi/2pi
    UNSTABLE = "unstable"  # converged on the branch, but with a negative eigenvalue


class _ValueEnum(str, enum.Enum):
    """A str enum that compares equal to, prints and formats as its value (what studies write
    to JSON)."""

    def __str__(self):
        return self.value

    def __format__(self, spec):
        return format(self.value, spec)


class BranchEnd(_ValueEnum):
    """How a followed stable branch ended."""

    UNSTABLE = "unstable"  # the corrector stayed on the branch, which acquired a negative eigenvalue
    JUMP = "jump"  # the minimiser left the branch (a fold, or a subcritical bifurcation)


@dataclass(frozen=True)
class _Refusal:
    failure: StepFailure
    detail: str

    def __str__(self):
        return f"{self.failure.value}: {self.detail}"


class NoCrossingError(RuntimeError):
    """The negative-eigenvalue count did not change over the scanned range of phi."""


@dataclass(frozen=True)
class CriticalPoint:
    """A twist at which an eigenvalue of the equilibrium branch crosses zero.

    phi: critical twist (rad); eigenvalue: crossing eigenvalue there (~0, dimensionless);
    dlambda_dphi: its derivative along the branch; mode: (n,) critical eigenvector (scaled DOFs);
    equilibrium: the branch state at the last evaluated twist (within phi_error of phi); multiplicity: change of the negative count (2 for a
    degenerate pair, as in the ring); bracket: (phi_a, phi_b) where the count changed;
    phi_error: size of the last Newton correction (an upper bound on the error once converged);
    hessian_evaluations: spectra computed in the refinement (bracket ends included);
    scan: list of (phi, n_negative, lowest eigenvalues), one entry per scan step.
    """

    phi: float
    eigenvalue: float
    dlambda_dphi: float
    mode: np.ndarray
    equilibrium: Equilibrium
    multiplicity: int
    bracket: tuple
    phi_error: float
    hessian_evaluations: int
    scan: list = field(repr=False)
    seconds: float = 0.0
    scene: object = field(default=None, repr=False)  # the scene as used last (fresh contact list)


# Near-zero modes of a loose knot (strands sliding along each other) sit at |lambda| ~ 1e-7 in the
# scaled units and change sign from step to step: with self-contact an eigenvalue counts as
# negative, and enters the branch tangent, only beyond this.
CONTACT_NEGATIVE_TOL = 1e-6
# Damped-Newton iterations a continuation corrector may take between two neighbourhood pauses.
# From the tangent predictor a step converges in 2-15; one still crawling after 60 is not near
# its branch (seen: 500 iterations, 9 s, on a trefoil past its fold) and the step is refused.
CORRECTOR_MAX_STEPS = 60
# The corrector's gradient tolerance with contact: the residual along the sliding modes relaxes
# only as fast as their ~1e-8 stiffness allows, and barely couples to the crossing eigenvalue.
# 1e-7 (forces in units of B/l^2) is ~1e-7 of the twist moments in a twisted knot.
CONTACT_GTOL = 1e-7


class Task(str, enum.Enum):
    """What a continuation is for: its defaults differ (see ``ContinuationOptions``)."""

    CRITICAL_TWIST = "critical_twist"  # the first crossing, refined by Newton on the eigenvalue
    FOLLOW_TWIST = "follow_twist"  # a whole stable path, branch ends located to tol


@dataclass(frozen=True)
class ContinuationOptions:
    """Tolerances and budgets of a twist continuation, every contact-aware default in one place.

    step: largest step in phi (rad). Default: critical_twist |phi_stop - phi_start| / 40,
      follow_twist 0.25 pi.
    tol: accuracy of the located critical twist or branch end (rad). Default: critical_twist
      1e-6 pi, follow_twist 2e-4 pi.
    negative_tol: an eigenvalue counts as negative below -negative_tol. Default 1e-10, or
      CONTACT_NEGATIVE_TOL = 1e-6 with self-contact (strands sliding along each other sit at
      |lambda| ~ 1e-7 and must not count).
    gtol: the equilibria's max |gradient| (scaled energy). Default 1e-9; critical_twist with
      contact CONTACT_GTOL = 1e-7 (the sliding modes relax only as fast as their stiffness allows).
    jump_tol: follow_twist: a corrector further than this from the predicted shape has left the
      branch. Default D/2 (or L/20 without a diameter).
    k: eigenpairs kept per state (default 8).
    corrector_max_steps: damped-Newton iterations a follow_twist corrector may take between two
      neighbourhood pauses (default CORRECTOR_MAX_STEPS = 60).

    None means "the default for the scene and task": ``resolved(scene, task, span)`` fills them
    in (and checks the values); ``critical_twist`` and ``follow_twist`` take an ``options`` object
    and/or the same names as keywords (a keyword that is not None wins).
    """

    step: float | None = None
    tol: float | None = None
    negative_tol: float | None = None
    gtol: float | None = None
    jump_tol: float | None = None
    k: int | None = None
    corrector_max_steps: int | None = None

    def updated(self, **values):
        """A copy with every value that is not None replaced."""
        return replace(self, **{key: v for key, v in values.items() if v is not None})

    def resolved(self, scene, task, span):
        """Every None filled in for ``scene`` (with or without contact) and ``task`` (a ``Task``);
        span: |phi_stop - phi_start|. Raises ValueError naming a non-positive or non-finite value."""
        task = Task(task)
        contact = "contact" in scene.terms
        critical = task is Task.CRITICAL_TWIST
        defaults = {
            "step": span / 40.0 if critical else 0.25 * math.pi,
            "tol": 1e-6 * math.pi if critical else 2e-4 * math.pi,
            "negative_tol": CONTACT_NEGATIVE_TOL if contact else DEFAULT_NEGATIVE_TOL,
            "gtol": CONTACT_GTOL if (contact and critical) else 1e-9,
            "jump_tol": _jump_tolerance(scene),
            "k": 8,
            "corrector_max_steps": CORRECTOR_MAX_STEPS,
        }
        values = {key: getattr(self, key) if getattr(self, key) is not None else d for key, d in defaults.items()}
        for key in ("step", "tol", "negative_tol", "gtol", "jump_tol"):
            values[key] = check_positive(key, abs(values[key]) if key == "step" else values[key])
        for key in ("k", "corrector_max_steps"):
            values[key] = check_int_at_least(key, values[key], 1)
        return ContinuationOptions(**values)


def _step(scene, phi, q_pred, index, k, negative_tol, fallback_q=None, ref=None, gtol=1e-9, nbr=None,
          sparse=False, guess=None):
    """Newton corrector from the predictor (the neighbourhood is rebuilt, and the solve
    repeated, if nodes moved out of it), then one spectrum. Returns (scene, equilibrium with its
    stability, tracked eigenvalue, its phi-derivative, its eigenvector, branch tangent dq/dphi).
    sparse: the O(N) block-tridiagonal corrector and analysis (``jaxrod.sparse_branch``); guess:
    an estimate of the lowest eigenvalue there (sparse only: it picks the eigensolver's shift)."""
    contact = "contact" in scene.terms
    near_null = negative_tol if contact else 0.0

    def correct(q_start):
        if sparse:
            return solve_equilibrium_sparse(scene, phi, q_start, gtol=gtol, nbr=nbr)
        return solve_equilibrium(scene, phi, q_start, method="newton", with_stability=False,
                                 near_null_tol=near_null, gtol=gtol, nbr=nbr)

    try:
        e = correct(q_pred)
    except ConvergenceError:
        if fallback_q is None:
            raise
        e = correct(fallback_q)
    pinv_tol = negative_tol if contact else 0.0
    analysis = sparse_branch_analysis if sparse else branch_analysis
    stab, lam, dlam, v, dq = analysis(scene, e.q, phi, index, k=k, tol=negative_tol, ref=ref, pinv_tol=pinv_tol,
                                      nbr=e.neighbourhood, guess=guess)
    return scene, replace(e, stability=stab), lam, dlam, v, dq


# "auto" takes the O(n) block path from this many DOFs on (N ~ 250 nodes): below it the dense
# path is fast enough, and compiled already for most small scenes.
_SPARSE_MIN_DOF = 1000


def _use_sparse(scene, linear_algebra):
    """Whether ``critical_twist`` uses the block path (see its ``linear_algebra``)."""
    if linear_algebra not in ("auto", "dense", "sparse"):
        raise ValueError(f"linear_algebra must be 'auto', 'dense' or 'sparse', got {linear_algebra!r}")
    if linear_algebra == "sparse" and "contact" in scene.terms:
        raise ValueError("linear_algebra='sparse' does not handle self-contact: use 'dense'")
    if linear_algebra == "auto":
        return "contact" not in scene.terms and scene.n_dof >= _SPARSE_MIN_DOF
    return linear_algebra == "sparse"


def critical_twist(
    scene,
    phi_start=0.0,
    phi_stop=None,
    step=None,
    q0=None,
    tol=None,
    k=None,
    negative_tol=None,
    max_refine=30,
    progress=None,
    gtol=None,
    linear_algebra="auto",
    options=None,
):
    """First phi beyond ``phi_start`` (in the direction of ``phi_stop``) where the negative count
    of the equilibrium branch changes.

    Tolerances (step, tol, negative_tol, gtol, k): keywords or an ``options``
    (``ContinuationOptions``, where their scene-aware defaults are defined); a keyword that is not
    None wins. scene: a scene; q0: initial guess at phi_start (default scene.q_init, relaxed first);
    step: largest scan step (default |phi_stop - phi_start|/40); the scan shortens it when the
    tracked eigenvalue, extrapolated with its derivative, is about to cross (never lengthens it:
    a mode from higher up is still caught by the count). tol: requested accuracy in phi.
    negative_tol: an eigenvalue counts as negative below -negative_tol (default 1e-10, or
    CONTACT_NEGATIVE_TOL = 1e-6 for scenes with self-contact, whose sliding modes sit at ~1e-7).
    Scenes with contact get their candidate list rebuilt along the way. gtol: the equilibria's
    gradient tolerance (default 1e-9, or CONTACT_GTOL = 1e-7 with contact).
    progress: optional callable(str) for progress lines.
    linear_algebra: "dense" (n x n Hessian, ``eigh``: O(n^3) per step), "sparse" (block-tridiagonal
    Newton, inertia, eigenpairs and tangent of ``jaxrod.sparse_branch``: O(n) per step; not with
    contact) or "auto" (sparse for scenes without contact with n_dof >= 1000, else dense). With
    "sparse" the stability's eigenvectors are the k lowest only, so the crossing mode must be
    among them (k > the negative count). Returns a ``CriticalPoint``; raises
    ``NoCrossingError`` if the count never changes before phi_stop.
    """
    t0 = time.perf_counter()
    phi_start = check_finite("phi_start", phi_start)
    phi_stop = check_finite("phi_stop", 8.0 * math.pi if phi_stop is None else phi_stop)
    if phi_stop == phi_start:
        raise ValueError("phi_stop must differ from phi_start")
    opts = (options or ContinuationOptions()).updated(step=step, tol=tol, negative_tol=negative_tol, gtol=gtol, k=k)
    opts = opts.resolved(scene, Task.CRITICAL_TWIST, abs(phi_stop - phi_start))
    tol, negative_tol, gtol, k, max_step = opts.tol, opts.negative_tol, opts.gtol, opts.k, opts.step
    contact = "contact" in scene.terms
    direction = 1.0 if phi_stop > phi_start else -1.0
    min_step = max_step / 16.0
    say = progress or (lambda s: None)
    sparse = _use_sparse(scene, linear_algebra)
    analysis = sparse_branch_analysis if sparse else branch_analysis

    if contact:
        relaxed = relax(scene, phi_start, q0, with_stability=False, gtol=gtol)
    elif sparse and scene.n_dof >= _SPARSE_MIN_DOF:
        # Large n: no dense relaxation (O(n^3) per step); Newton from q0 (for rings and straight
        # clamped rods the initial shape already is the equilibrium, up to the twist angles).
        relaxed = solve_equilibrium_sparse(scene, phi_start, q0, gtol=gtol)
    else:
        relaxed = solve_equilibrium(scene, phi_start, q0, method="auto", with_stability=False, gtol=gtol)
    pinv_tol = negative_tol if contact else 0.0
    st0, lam_t, dlam_t, _, dq = analysis(scene, relaxed.q, phi_start, 0, k=k, tol=negative_tol,
                                         pinv_tol=pinv_tol, nbr=relaxed.neighbourhood)
    count0 = int(st0.n_negative)
    # The eigenvalue that crosses next: the lowest one clearly above zero (near-zero modes skipped).
    index = int(np.sum(st0.eigenvalues < negative_tol)) if st0.eigenvalues.size else 0
    if index != 0:
        st0, lam_t, dlam_t, _, dq = analysis(
            scene, relaxed.q, phi_start, index, k=k, tol=negative_tol, pinv_tol=pinv_tol, nbr=relaxed.neighbourhood
        )
    prev = replace(relaxed, stability=st0)
    scan = [(prev.phi, count0, prev.stability.eigenvalues.copy())]
    say(f"phi = {prev.phi / math.pi:+.4f} pi: {count0} negative, lowest {prev.stability.eigenvalues[0]:.3e}")

    # Scan with a tangent predictor until the count changes.
    h = max_step
    before = None  # the scan state before prev (a fallback stable end for the refinement)
    while True:
        phi_next = prev.phi + direction * h
        if direction * (phi_next - phi_stop) > 1e-12:
            raise NoCrossingError(
                f"negative count stayed {count0} from phi = {phi_start:.6g} to {phi_stop:.6g}"
            )
        try:
            scene, cur, lam_c, dlam_c, _, dq_c = _step(
                scene, phi_next, prev.q + dq * (phi_next - prev.phi), index, k, negative_tol, prev.q, gtol=gtol,
                nbr=prev.neighbourhood, sparse=sparse,
                guess=min(prev.stability.eigenvalues[0], lam_t + dlam_t * (phi_next - prev.phi)),
            )
        except ConvergenceError:
            # Step-size control: no equilibrium found near the predictor; halve the step. If even
            # tiny steps fail, the branch ends here (a fold: the state must jump elsewhere).
            h *= 0.5
            if h < max_step / 1024.0:
                raise ConvergenceError(
                    f"the equilibrium branch could not be followed beyond phi = {prev.phi:.8g} "
                    f"({prev.phi / math.pi:.6f} pi): steps down to {2 * h:.2e} failed (a fold or a jump?)"
                ) from None
            say(f"corrector failed at phi = {phi_next / math.pi:+.4f} pi: step halved to {h:.3e}")
            continue
        scan.append((cur.phi, cur.stability.n_negative, cur.stability.eigenvalues.copy()))
        say(
            f"phi = {cur.phi / math.pi:+.4f} pi: {cur.stability.n_negative} negative, "
            f"lowest {cur.stability.eigenvalues[:3]}"
        )
        if cur.stability.n_negative != count0:
            break
        # Newton-extrapolated crossing of the tracked eigenvalue: aim 10% past it.
        h = max_step
        if dlam_c != 0.0:
            ahead = -lam_c / dlam_c * direction
            if ahead > 0.0:
                h = min(max_step, max(min_step, 1.1 * ahead))
        before, prev, dq, lam_t, dlam_t = prev, cur, dq_c, lam_c, dlam_c

    # Refine. The crossing mode: at the far end, the negative eigenvalue nearest zero; followed
    # by eigenvector overlap from there on (robust to reordering and to near-zero modes).
    multiplicity = abs(cur.stability.n_negative - count0)
    lo, hi = prev, cur
    ev_hi = cur.stability.eigenvalues
    neg = np.nonzero(ev_hi < -negative_tol)[0]
    if cur.stability.n_negative > count0 and neg.size:
        idx_hi = int(neg[-1])
    else:  # the count went down: a negative eigenvalue became positive
        idx_hi = int(np.sum(ev_hi < negative_tol))
    ref = cur.stability.eigenvectors[:, idx_hi]
    evals = 2
    _, f_hi, _, v_hi, _ = analysis(scene, hi.q, hi.phi, idx_hi, k=k, tol=negative_tol, ref=ref, pinv_tol=pinv_tol,
                                   nbr=hi.neighbourhood, guess=hi.stability.eigenvalues[0])
    _, f_lo, d_lo, v_lo, dq_lo = analysis(scene, lo.q, lo.phi, 0, k=k, tol=negative_tol, ref=v_hi, pinv_tol=pinv_tol,
                                          nbr=lo.neighbourhood, guess=lo.stability.eigenvalues[0])
    if np.sign(f_lo) == np.sign(f_hi) and before is not None:
        # The crossing eigenvalue already changed sign at lo but stayed inside the near-zero band
        # (|lambda| < negative_tol, e.g. a soft ring of N ~ 1000, lambda ~ 1e-9): the count missed
        # it there. Take the scan state before as the stable end, so that the bracket holds a sign
        # change (the sign tests below rely on it).
        lo, evals = before, 3
        _, f_lo, d_lo, v_lo, dq_lo = analysis(scene, lo.q, lo.phi, 0, k=k, tol=negative_tol, ref=v_hi,
                                              pinv_tol=pinv_tol, nbr=lo.neighbourhood,
                                              guess=lo.stability.eigenvalues[0])
    evals = max(evals, 2)
    bracket = (lo.phi, hi.phi)
    # First guess: Newton from the stable end if it stays inside the bracket, else secant.
    a, b = sorted(bracket)
    phi_c = lo.phi - f_lo / d_lo if d_lo != 0.0 else math.nan
    if not (math.isfinite(phi_c) and a < phi_c < b):
        phi_c = lo.phi - f_lo * (hi.phi - lo.phi) / (f_hi - f_lo)
    base, base_dq, v_ref, f_base, d_base = lo, dq_lo, v_lo, f_lo, d_lo
    phi_error = abs(hi.phi - lo.phi)
    for _ in range(max_refine):
        scene, e, f_c, d_c, v_c, dq_c = _step(
            scene, phi_c, base.q + base_dq * (phi_c - base.phi), 0, k, negative_tol, base.q, ref=v_ref, gtol=gtol,
            nbr=base.neighbourhood, sparse=sparse,
            guess=min(base.stability.eigenvalues[0], f_base + d_base * (phi_c - base.phi)),
        )
        evals += 1
        if np.sign(f_c) == np.sign(f_lo):
            lo, f_lo = e, f_c
        else:
            hi, f_hi = e, f_c
        newton = phi_c - f_c / d_c if d_c != 0.0 else math.nan
        a, b = sorted((lo.phi, hi.phi))
        if not (math.isfinite(newton) and a <= newton <= b):
            newton = lo.phi - f_lo * (hi.phi - lo.phi) / (f_hi - f_lo)  # regula falsi fallback
            if not (a < newton < b):
                newton = 0.5 * (a + b)
        phi_error = abs(newton - phi_c)
        base, base_dq, v_ref, f_base, d_base = e, dq_c, v_c, f_c, d_c
        say(f"refine: phi = {phi_c / math.pi:.12f} pi, eigenvalue {f_c:+.3e}, next step {phi_error:.2e}")
        if phi_error < tol or f_c == 0.0:
            break
        phi_c = newton
    else:
        raise ConvergenceError(f"critical twist refinement did not reach tol = {tol:.3g} in {max_refine} steps")

    # Report the last Newton update: its error is quadratically smaller than phi_error, which
    # stays as a conservative bound.
    return CriticalPoint(
        phi=float(newton),
        eigenvalue=float(f_c),
        dlambda_dphi=float(d_c),
        mode=v_c,
        equilibrium=e,
        multiplicity=multiplicity,
        bracket=bracket,
        phi_error=float(phi_error),
        hessian_evaluations=evals,
        scan=scan,
        seconds=time.perf_counter() - t0,
        scene=scene,
    )


# ---------------------------------------------------------------------------------------------
# Following a stable branch through its instabilities, with branch switching (knots).
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BranchPoint:
    """One accepted continuation step: ``equilibrium`` (with its stability) on the branch named
    ``branch``; ``tangent``: dq/dphi there (physical DOFs, near-zero modes left out);
    ``scene``: the scene with its contact list valid at this state."""

    branch: str
    equilibrium: Equilibrium
    tangent: np.ndarray = field(repr=False)
    scene: object = field(repr=False)


@dataclass(frozen=True)
class Instability:
    """Where a followed stable branch stops being one.

    phi: estimate (the bracket's midpoint); phi_error: half the bracket; bracket: (last stable
    twist reached, nearest twist where the branch was lost); kind: 'unstable' (the corrector
    still converged on the branch, which had acquired negative eigenvalues) or 'jump' (the
    minimiser left the branch: a fold, or a subcritical bifurcation whose unstable branch it
    cannot stay on); multiplicity: how many eigenvalues go soft together (2 for a symmetric
    pair); eigenvalue,
    dlambda_dphi, mode: the critical eigenvalue at the last stable state, its derivative along
    the branch and its eigenvector (scaled DOFs); equilibrium: that last stable state;
    from_branch / to_branch: branch names (to_branch None if no switch was made); jumped_to:
    the first state of the new branch (or None).
    """

    phi: float
    phi_error: float
    bracket: tuple
    kind: str
    multiplicity: int
    eigenvalue: float
    dlambda_dphi: float
    mode: np.ndarray = field(repr=False)
    equilibrium: Equilibrium = field(repr=False)
    from_branch: str = ""
    to_branch: str | None = None
    negative_tol: float = 0.0
    dlambda_dphi_secant: float = math.nan
    jumped_to: Equilibrium | None = field(default=None, repr=False)


class PathStop(_ValueEnum):
    """Why ``follow_twist`` stopped."""

    PHI_STOP = "phi_stop"  # the whole range was covered
    BRANCH_ENDED = "branch_ended"  # a branch ended, and no switch was to be made (switch=False, max_switches)
    NO_STABLE_BRANCH = "no_stable_branch"  # a branch ended and no stable state was found beyond it


@dataclass(frozen=True)
class TwistPath:
    """Result of ``follow_twist``: ``points`` (BranchPoint per accepted step, in order),
    ``instabilities`` (Instability per branch end met), ``stop`` (a ``PathStop``), ``reason``
    (the same in words, with the twist where it happened), ``seconds``."""

    points: list
    instabilities: list
    reason: str
    seconds: float
    stop: PathStop = PathStop.PHI_STOP

    @property
    def completed(self):
        return self.stop is PathStop.PHI_STOP


def _jump_tolerance(scene):
    D = scene.material.D
    return 0.5 * float(D) if D is not None else 0.05 * float(scene.length)


def follow_twist(
    scene,
    phi_start=0.0,
    phi_stop=None,
    step=None,
    q0=None,
    start=None,
    tol=None,
    branch="symmetric",
    k=None,
    negative_tol=None,
    gtol=None,
    jump_tol=None,
    switch=True,
    max_switches=3,
    perturbation=None,
    on_point=None,
    progress=None,
    options=None,
    on_instability=None,
):
    """Follow the stable equilibrium branch from phi_start towards phi_stop; where it ends
    (an eigenvalue crosses zero or the branch folds), locate the end to ``tol`` and switch to the
    stable buckled branch along the critical eigenvector, then go on.

    Predictor: the branch tangent dq/dphi (implicit function theorem, near-zero sliding modes
    left out). Corrector: the damped-Newton minimiser of ``relax`` (exact Hessian, capped steps,
    contact lists rebuilt, strand passage refused), which cannot wander onto an unstable branch.
    A step is accepted when the corrector converges, the state stays within ``jump_tol``
    (default D/2) of the predicted shape (a distance blind to material sliding along the
    centreline), the linking number is Lk0 + phi/2 pi (closed rods) and no eigenvalue is below
    -negative_tol. Otherwise the step is halved; once the failing twist is within ``tol`` of the
    last accepted one, the branch has ended there (a failure that persists as the step goes to
    zero is not a step-size artefact). Near-zero modes (|lambda| < negative_tol: strands sliding
    in a loose knot, ~1e-7) never count.

    Branch switching: at the nearest twist where the branch was lost, the predicted state is
    pushed by +-``perturbation`` (default D/2 at the node that moves most) along the critical
    eigenvector and relaxed; the lower-energy stable state away from the old branch is the new
    branch ("buckled", then "buckled2", ...; the sign of the direction is appended).

    Tolerances (step, tol, negative_tol, gtol, jump_tol, k): keywords or an ``options``
    (``ContinuationOptions``, where their scene-aware defaults are defined; a keyword that is not
    None wins). scene: closed or clamped rod scene; q0 or start (an Equilibrium to begin from,
    used as is); step: largest step in phi (default 0.25 pi); on_point(BranchPoint) and progress(str): callbacks (e.g. to write
    rows as they come); on_instability(Instability): called as soon as a branch end is located
    (and, after a switch, before the new branch's first point), so that a study can keep it on
    file at once. Returns a ``TwistPath``.
    """
    t0 = time.perf_counter()
    phi_start = check_finite("phi_start", phi_start if start is None else start.phi)
    phi_stop = check_finite("phi_stop", 8.0 * math.pi if phi_stop is None else phi_stop)
    if phi_stop == phi_start:
        raise ValueError("phi_stop must differ from phi_start")
    opts = (options or ContinuationOptions()).updated(step=step, tol=tol, negative_tol=negative_tol, gtol=gtol,
                                                      jump_tol=jump_tol, k=k)
    opts = opts.resolved(scene, Task.FOLLOW_TWIST, abs(phi_stop - phi_start))
    step, tol, negative_tol, gtol, jump_tol, k = opts.step, opts.tol, opts.negative_tol, opts.gtol, opts.jump_tol, opts.k
    corrector_max_steps = opts.corrector_max_steps
    contact = "contact" in scene.terms
    direction = 1.0 if phi_stop > phi_start else -1.0
    sign = "+" if direction > 0 else "-"
    say = progress or (lambda s: None)
    closed = bool(scene.closed)
    lk0 = float(getattr(scene, "Lk0", 0.0))

    def analyse(sc, e):
        st, _, _, _, dq = branch_analysis(sc, e.q, e.phi, 0, k=k, tol=negative_tol, pinv_tol=pinv_tol,
                                          nbr=e.neighbourhood)
        return replace(e, stability=st), dq

    def attempt(sc, prev, dq, phi):
        """Corrector from the tangent predictor. Returns (ok, why, scene, equilibrium, tangent)."""
        q_pred = prev.q + dq * (phi - prev.phi)
        x_pred = np.asarray(sc.positions(jnp.asarray(q_pred)))
        try:
            e = relax(sc, phi, q_pred, gtol=gtol, previous=prev, with_stability=False, nbr=prev.neighbourhood,
                      guide=(x_pred, jump_tol), max_steps=corrector_max_steps)
            sc2 = sc
        except LeftBranchError as exc:
            return False, _Refusal(StepFailure.JUMP, str(exc)), sc, None, None
        except TopologyChangeError as exc:
            return False, _Refusal(StepFailure.TOPOLOGY, str(exc)), sc, None, None
        except ConvergenceError as exc:
            return False, _Refusal(StepFailure.NOT_CONVERGED, str(exc)), sc, None, None
        moved = polyline_distance(e.x, x_pred, closed)
        if moved > jump_tol:
            return False, _Refusal(StepFailure.JUMP, f"the state moved {moved:.3g} from the predicted shape"), sc2, e, None
        e, dq2 = analyse(sc2, e)
        if closed and abs(e.Lk - (lk0 + phi / (2.0 * math.pi))) > 1e-6:
            return False, _Refusal(StepFailure.LINKING, f"Lk = {e.Lk:.8f} is not Lk0 + phi/2pi"), sc2, e, None
        if e.stability.n_negative > 0 and contact:
            # A soft, sliding-type mode of a loose knot may turn slightly negative: the minimiser
            # then stalls on a saddle that differs from a stable state only by a slide of the
            # material along the same shape. Push along the negative mode and relax: if a stable
            # state of the *same shape* appears, the branch goes on (no false detection).
            escaped = _escape_soft_saddle(sc2, e, prev, x_pred, jump_tol, gtol, closed, analyse)
            if escaped is not None:
                sc2, e, dq2 = escaped
        if e.stability.n_negative > 0:
            return False, _Refusal(StepFailure.UNSTABLE, f"{e.stability.n_negative} negative eigenvalue(s)"), sc2, e, dq2
        return True, "", sc2, e, dq2

    def emit(name, sc, e, dq):
        point = BranchPoint(branch=name, equilibrium=e, tangent=dq, scene=sc)
        points.append(point)
        if on_point is not None:
            on_point(point)
        lam = e.stability.eigenvalues
        say(f"[{name}] phi = {e.phi / math.pi:+.5f} pi: E = {e.energy:.6g}, Wr = {e.Wr:.4f}, "
            f"Tw = {e.Tw:.4f}, {e.stability.n_negative} negative, lowest " + " ".join(f"{v:.2e}" for v in lam[:3]))
        return point

    points, instabilities = [], []
    if start is None:
        e0 = relax(scene, phi_start, q0, gtol=gtol, with_stability=False)
    else:
        e0 = start
        if e0.neighbourhood is None:
            e0 = replace(e0, neighbourhood=scene.neighbourhood(e0.q, e0.phi))
    pinv_tol = negative_tol if contact else 0.0
    e0, dq = analyse(scene, e0)
    name = f"{branch}{sign}"
    emit(name, scene, e0, dq)
    prev, older = e0, None
    h = step
    switches = 0
    reason, stop = "phi_stop", PathStop.PHI_STOP
    while direction * (phi_stop - prev.phi) > 1e-12:
        # Steps land on the grid of multiples of ``step`` (so whole turns are visited, where the
        # ribbon closes and the Gauss linking number can be compared) unless shortened.
        grid = step * (math.floor(prev.phi / step + 1e-9) + 1 if direction > 0 else math.ceil(prev.phi / step - 1e-9) - 1)
        phi_next = prev.phi + direction * min(h, abs(phi_stop - prev.phi), abs(grid - prev.phi))
        ok, why, sc, e, dq_new = attempt(scene, prev, dq, phi_next)
        if ok:
            older, (scene, prev, dq) = prev, (sc, e, dq_new)
            emit(name, scene, e, dq)
            h = min(step, 2.0 * h)
            continue
        # The branch was lost at phi_next: shrink the bracket between the last stable state and
        # there to tol, aiming each trial with a model of the critical eigenvalue (a few solves
        # where bisection needs ~log2(step/tol) ~ 11).
        lost_phi, lost_why, lost_eq = phi_next, why, e
        say(f"[{name}] lost at phi = {phi_next / math.pi:+.5f} pi ({why}); locating the end")
        lost_from = prev.phi
        failures, successes, probe_held = 0, 0, False
        while abs(lost_phi - prev.phi) > tol:
            trial, probe = _end_trial(older, prev, lost_phi, lost_eq, direction, tol, negative_tol,
                                      failures, probe_held, successes)
            ok, why, sc, e, dq_new = attempt(scene, prev, dq, trial)
            if ok:
                older, (scene, prev, dq) = prev, (sc, e, dq_new)
                emit(name, scene, e, dq)
                failures, successes, probe_held = 0, successes + 1, probe
            else:
                say(f"[{name}] phi = {trial / math.pi:+.5f} pi refused ({why})")
                lost_phi, lost_why, lost_eq, lost_from = trial, why, e, prev.phi
                failures, successes, probe_held = failures + 1, 0, False
        if abs(lost_phi - lost_from) > tol:
            # The nearest failure was met from a state further back: confirm it from the last
            # stable state, so that a predictor too far off is not taken for the branch's end.
            ok, why, sc, e, dq_new = attempt(scene, prev, dq, lost_phi)
            if ok:
                say(f"[{name}] phi = {lost_phi / math.pi:+.5f} pi reached from closer by: going on")
                older, (scene, prev, dq) = prev, (sc, e, dq_new)
                emit(name, scene, e, dq)
                # The step that failed was too long for the predictor, not past the end: go on
                # with half of it (not from 2 tol, which needs ~10 doublings back to ``step``).
                h = max(2.0 * tol, 0.5 * abs(lost_phi - lost_from))
                continue
            lost_why, lost_eq = why, e
        kind = BranchEnd.UNSTABLE if lost_why.failure is StepFailure.UNSTABLE else BranchEnd.JUMP
        inst = _critical_mode(scene, prev, older, lost_eq, kind, direction, k, negative_tol, pinv_tol)
        rate = inst.dlambda_dphi if kind is BranchEnd.UNSTABLE or not math.isfinite(inst.dlambda_dphi_secant) \
            else inst.dlambda_dphi_secant
        phi_c, phi_err = _locate(prev.phi, lost_phi, inst.eigenvalue, rate, direction)
        inst = replace(inst, phi=phi_c, phi_error=phi_err, bracket=(prev.phi, lost_phi), from_branch=name,
                       negative_tol=negative_tol)
        say(f"[{name}] branch ends at phi* = {inst.phi / math.pi:+.6f} pi +- {inst.phi_error:.1e} rad "
            f"({kind}; last: {lost_why}); critical eigenvalue {inst.eigenvalue:.3e}, "
            f"d/dphi {inst.dlambda_dphi:.3e}")
        if not switch or switches >= max_switches:
            instabilities.append(inst)
            if on_instability is not None:
                on_instability(inst)
            reason, stop = f"branch ended at phi = {inst.phi:.8g} ({kind})", PathStop.BRANCH_ENDED
            break
        switches += 1
        new_name = _next_branch_name(name[:-1]) + sign
        found = _switch_branch(scene, prev, dq, lost_phi, inst.mode, lost_eq, perturbation, jump_tol,
                               gtol, analyse, closed, lk0, say)
        if found is None:
            instabilities.append(inst)
            if on_instability is not None:
                on_instability(inst)
            reason, stop = f"no stable branch found beyond phi = {lost_phi:.8g}", PathStop.NO_STABLE_BRANCH
            break
        sc, e, dq_new = found
        instabilities.append(replace(inst, to_branch=new_name, jumped_to=e))
        if on_instability is not None:  # before the new branch's first point is reported
            on_instability(instabilities[-1])
        scene, prev, dq, name, older = sc, e, dq_new, new_name, None
        emit(name, scene, e, dq)
        h = step
    return TwistPath(points=points, instabilities=instabilities, reason=reason, seconds=time.perf_counter() - t0,
                     stop=stop)


def _critical_candidates(older, prev, negative_tol, candidates=5):
    """(lambda_prev, lambda_older, eigenvector) of the lowest eigen-modes of ``prev`` above the
    near-zero band, each matched in ``older`` by eigenvector overlap (no new spectrum needed)."""
    st, so = prev.stability, older.stability
    if st is None or so is None:
        return []
    out = []
    for j in range(min(candidates, len(st.eigenvalues))):
        lam = float(st.eigenvalues[j])
        if abs(lam) <= negative_tol:
            continue
        v = np.asarray(st.eigenvectors[:, j])
        ov = np.abs(np.asarray(so.eigenvectors).T @ v)
        out.append((lam, float(so.eigenvalues[int(np.argmax(ov))]), v))
    return out


def _end_trial(older, prev, phi_lost, lost_eq, direction, tol, negative_tol, failures, probe_held, successes=0):
    """The next twist to try when locating where a branch ends, between the last stable state
    ``prev`` and the nearest twist ``phi_lost`` where the branch was lost. Returns (phi, probe).

    Model: near a fold the critical eigenvalue goes like sqrt(phi* - phi), so lambda^2 is linear
    in phi; its secant through ``older`` and ``prev`` (the mode that reaches zero first) gives
    phi*, never beyond it at a transversal crossing (where it lands short). When the lost state
    is an equilibrium with a negative eigenvalue (a crossing), lambda is interpolated linearly
    between the two ends instead. The trial aims 0.3 tol short of phi*, or, when the stable end
    is already there, probes 0.9 tol beyond it (probe = True), so that a good model closes the
    bracket to tol in two solves. Safeguards: bisection when there is no model, after two
    failures or two successes in a row (a model that keeps landing short converges on a point
    that is not the end: the stable end would creep towards it), after a probe that held, or
    when the model lands outside the inner 90% of the bracket."""
    width = direction * (phi_lost - prev.phi)
    mid = prev.phi + 0.5 * direction * width
    if failures >= 2 or successes >= 2 or probe_held or older is None or older.phi == prev.phi:
        return mid, False
    estimates = []
    for lam, lam_old, v in _critical_candidates(older, prev, negative_tol):
        if lam <= 0.0:
            continue
        if lost_eq is not None and lost_eq.stability is not None:
            ov = np.abs(np.asarray(lost_eq.stability.eigenvectors).T @ v)
            lam_lost = float(lost_eq.stability.eigenvalues[int(np.argmax(ov))])
            if lam_lost < -negative_tol and ov.max() > 0.5:
                # The branch is lost where lambda passes -negative_tol (the stability test's
                # threshold), not where it passes zero: aim there, or the lost end creeps
                # towards a lambda of -negative_tol and the bracket barely shrinks.
                estimates.append(prev.phi + (phi_lost - prev.phi) * (lam + negative_tol) / (lam - lam_lost))
                continue
        slope = (lam**2 - lam_old**2) / (prev.phi - older.phi)  # d(lambda^2)/dphi
        if direction * slope < 0.0 and lam < lam_old:
            estimates.append(prev.phi - lam**2 / slope)
    if not estimates:
        return mid, False
    est = min(estimates, key=lambda p: direction * (p - prev.phi))
    trial, probe = est - direction * 0.3 * tol, False
    if direction * (trial - prev.phi) < 0.5 * tol:
        trial, probe = prev.phi + direction * 0.9 * tol, True
    inside = direction * (trial - prev.phi) > 0.0 and direction * (phi_lost - trial) > 0.0
    lo, hi = prev.phi + direction * 0.05 * width, phi_lost - direction * 0.05 * width
    if direction * (trial - lo) >= 0.0 and direction * (hi - trial) >= 0.0:
        return trial, probe
    if inside and width < 4.0 * tol:
        return trial, probe
    return mid, False


def _locate(phi_stable, phi_lost, lam, dlam, direction):
    """phi* from the last stable state: the eigenvalue's Newton extrapolation phi - lam/dlam when
    it is close (it is exact to second order for a crossing, also when a slightly negative
    eigenvalue hid in the near-zero band; for a fold it lands within the bracket), otherwise the
    bracket midpoint. The error bound is half the bracket, or 10% of the extrapolation distance
    when that is larger."""
    mid, half = 0.5 * (phi_stable + phi_lost), 0.5 * abs(phi_lost - phi_stable)
    if dlam == 0.0 or not math.isfinite(dlam):
        return mid, half
    newton = phi_stable - lam / dlam
    reach = abs(newton - phi_stable)
    ahead = direction * (newton - phi_stable)
    if ahead <= 2.0 * half and reach <= max(40.0 * half, 0.1 * math.pi):
        return newton, max(half, 0.1 * reach)
    return mid, half


def _escape_soft_saddle(scene, e, prev, x_pred, jump_tol, gtol, closed, analyse):
    """From a saddle e, relax after pushes of +-jump_tol/4 along its most negative mode; return
    (scene, equilibrium, tangent) of a stable state within jump_tol of the predicted shape x_pred,
    or None."""
    v = np.asarray(e.stability.eigenvectors[:, 0])
    mode_q = scene.from_scaled(np.asarray(v))
    x_mode = np.asarray(scene.unpack(jnp.asarray(mode_q), 0.0)[0])
    amp = 0.25 * jump_tol / max(float(np.max(np.linalg.norm(x_mode, axis=1))), 1e-300)
    for sgn in (1.0, -1.0):
        try:
            # Guided: a push along a real buckling mode runs off the predicted shape and is
            # stopped at its first pause instead of being relaxed to the end.
            e2 = relax(scene, e.phi, e.q + sgn * amp * mode_q, gtol=gtol, previous=prev, with_stability=False,
                       nbr=e.neighbourhood, guide=(x_pred, jump_tol), max_steps=CORRECTOR_MAX_STEPS)
            sc2 = scene
        except (ConvergenceError, TopologyChangeError):
            continue
        if polyline_distance(e2.x, x_pred, closed) > jump_tol:
            continue
        e2, dq2 = analyse(sc2, e2)
        if e2.stability.n_negative == 0:
            return sc2, e2, dq2
    return None


def _next_branch_name(name):
    """symmetric -> buckled -> buckled2 -> buckled3 ..."""
    if not name.startswith("buckled"):
        return "buckled"
    tail = name[len("buckled"):]
    return f"buckled{int(tail) + 1 if tail.isdigit() else 2}"


def _critical_mode(scene, prev, older, lost_eq, kind, direction, k, negative_tol, pinv_tol, candidates=5):
    """The critical eigenpair at the last stable state ``prev``: of its lowest ``candidates``
    eigenvalues, the one that reaches zero first when extrapolated with its secant rate from the
    state before (``older``, matched by eigenvector overlap); without ``older``, with the
    autodiff derivative along the branch. The secant also holds at a fold, where the autodiff
    derivative of the fixed-branch linearisation does not (dlambda/dphi diverges there).
    Near-zero sliding modes hardly move with phi, so they lose to the mode really going soft.
    multiplicity: how many approach zero together (within a factor 3 in reach).
    Returns an Instability with dlambda_dphi (autodiff) and dlambda_dphi_secant."""
    st = prev.stability
    ev = st.eigenvalues
    found = []
    for j in range(min(candidates, len(ev))):
        _, lam_j, dlam_j, v_j, _ = branch_analysis(scene, prev.q, prev.phi, j, k=k, tol=negative_tol,
                                                   pinv_tol=pinv_tol, nbr=prev.neighbourhood)
        secant = math.nan
        if older is not None and older.stability is not None and older.phi != prev.phi:
            ov = np.abs(np.asarray(older.stability.eigenvectors).T @ np.asarray(v_j))
            secant = (lam_j - float(older.stability.eigenvalues[int(np.argmax(ov))])) / (prev.phi - older.phi)
        rate = -direction * (secant if math.isfinite(secant) else dlam_j)
        reach = (abs(lam_j) + 1e-12) / rate if rate > 0 else math.inf
        found.append((reach, lam_j, dlam_j, secant, v_j))
    found.sort(key=lambda f: f[0])
    reach, lam, dlam, secant, v = found[0]
    multiplicity = sum(1 for f in found if f[0] <= 3.0 * reach) if math.isfinite(reach) else 1
    return Instability(phi=prev.phi, phi_error=0.0, bracket=(prev.phi, prev.phi), kind=kind,
                       multiplicity=multiplicity, eigenvalue=float(lam), dlambda_dphi=float(dlam),
                       dlambda_dphi_secant=float(secant), mode=np.asarray(v), equilibrium=prev)


def _switch_branch(scene, prev, dq, phi, mode, lost_eq, perturbation, jump_tol, gtol, analyse, closed, lk0, say):
    """Relax from the predicted state pushed both ways along the critical mode (and from the
    state the corrector itself jumped to, if any); keep stable states away from the old branch
    with the right Lk; return the lowest in energy as (scene, equilibrium, tangent) or None."""
    q_pred = prev.q + dq * (phi - prev.phi)
    x_pred = np.asarray(scene.unpack(jnp.asarray(q_pred), phi)[0])
    mode_q = scene.from_scaled(np.asarray(mode))
    x_mode = np.asarray(scene.unpack(jnp.asarray(mode_q), 0.0)[0])
    biggest = float(np.max(np.linalg.norm(x_mode, axis=1)))
    amp = (jump_tol if perturbation is None else float(perturbation)) / max(biggest, 1e-300)
    starts = [("+mode", q_pred + amp * mode_q), ("-mode", q_pred - amp * mode_q)]
    # Where the corrector itself goes when left alone (it was stopped early while locating the
    # end, so that state is computed here, once).
    starts.append(("jumped", np.asarray(lost_eq.q) if lost_eq is not None else q_pred))
    best = None
    for label, q_start in starts:
        try:
            e = relax(scene, phi, q_start, gtol=gtol, previous=prev, with_stability=False, nbr=prev.neighbourhood)
            sc = scene
        except (ConvergenceError, TopologyChangeError) as exc:
            say(f"  switch from {label}: {type(exc).__name__}: {exc}")
            continue
        moved = polyline_distance(e.x, x_pred, closed)
        e, dq_e = analyse(sc, e)
        lk_ok = (not closed) or abs(e.Lk - (lk0 + phi / (2.0 * math.pi))) <= 1e-6
        say(f"  switch from {label}: E = {e.energy:.8g}, Wr = {e.Wr:.4f}, moved {moved:.3g}, "
            f"{e.stability.n_negative} negative, Lk ok: {lk_ok}")
        if moved <= jump_tol or not e.stability.stable or not lk_ok:
            continue
        if best is None or e.energy < best[1].energy:
            best = (sc, e, dq_e)
    return best
