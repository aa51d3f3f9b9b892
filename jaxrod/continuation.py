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
import warnings
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

import jax.numpy as jnp

from .equilibrium import (Equilibrium, LeftBranchError, TopologyChangeError, equilibrium_arrays, equilibrium_from_arrays,
                          mode_step, relax, solve_equilibrium)
from .geometry import polyline_distance
from .validation import check_finite, check_int_at_least, check_positive, refuse_knot
from .solvers import ConvergenceError
from .sparse_branch import EXTRA_PAIRS, solve_equilibrium_sparse, sparse_branch_analysis
from .stability import CONTACT_NEGATIVE_TOL, DEFAULT_NEGATIVE_TOL, branch_analysis, shape_modes_in_band  # noqa: F401 (re-exported)

__all__ = ["check_dense_memory", "dense_memory_bytes", "available_memory_bytes", "default_negative_tol",
           "ContinuationOptions", "Task", "PathStop", "StepFailure", "BranchEnd", "CriticalPoint", "critical_twist", "NoCrossingError", "BranchPoint", "Instability", "TwistPath", "follow_twist", "PathState", "Phase"]


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


# CONTACT_NEGATIVE_TOL (the near-zero band with self-contact) lives in .stability and is
# re-exported here, where callers have always found it.
# A follow_twist corrector out of steps with a gradient within this factor of gtol has stalled on
# sliding modes (seen: N = 151 trefoil, |g| ~ 7e-9 against 1e-9, a false branch end at -8.03 pi
# where the true one is -11.1 pi); Newton finishes it (``_Engine._finish_stalled``).
STALL_FACTOR = 100.0
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
            "negative_tol": CONTACT_NEGATIVE_TOL if contact else default_negative_tol(scene),
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


# Without contact, an eigenvalue counts as negative below -NEGATIVE_TOL_FRACTION times the bending
# scale (2 pi l / L)^4 of the rod (l the edge length, L the rod's length; in the scaled units the
# softest ring modes sit at 7.2 (2 pi / N)^4: 7.0e-10 at N = 2000, ~1e-12 at N = 10000), and never
# below DEFAULT_NEGATIVE_TOL. A fixed 1e-10 is far above those eigenvalues for N >~ 2000: the count
# changed a whole pi after the crossing (a ring of N = 2000 reported 6.27 pi for 5.20 pi) or all k
# eigenpairs computed were "near zero" (N >= 5800: "index 8 outside the 8 eigenpairs computed").
# Rods of N <= 628 nodes keep 1e-10.
NEGATIVE_TOL_FRACTION = 1e-2


def default_negative_tol(scene):
    """The continuations' negative tolerance for a scene without contact: DEFAULT_NEGATIVE_TOL,
    or NEGATIVE_TOL_FRACTION (2 pi l / L)^4 where that is smaller (long rods, whose softest modes
    go like N^-4 in the scaled units)."""
    ratio = 2.0 * math.pi * float(scene.length_scale) / float(scene.length)
    return min(DEFAULT_NEGATIVE_TOL, NEGATIVE_TOL_FRACTION * ratio**4)


@dataclass(frozen=True)
class _Step:
    """The outcome of one predictor-corrector step (``_Engine.step``).

    equilibrium: the corrected state (with its stability once analysed; None if the corrector
    failed); tangent: dq/dphi there; eigenvalue, dlambda_dphi, mode: the tracked eigenpair and
    its derivative along the branch; refusal: why the step was refused (None: accepted)."""

    equilibrium: Equilibrium | None
    tangent: np.ndarray | None = field(default=None, repr=False)
    eigenvalue: float = math.nan
    dlambda_dphi: float = math.nan
    mode: np.ndarray | None = field(default=None, repr=False)
    refusal: _Refusal | None = None

    @property
    def ok(self):
        return self.refusal is None


@dataclass(frozen=True)
class _Engine:
    """The one predictor-corrector-accept step that both continuations are loops over.

    Predictor: the branch tangent, q(phi) = q_prev + dq/dphi (phi - phi_prev). Corrector, by task:
    ``critical_twist`` uses Newton (it must also converge *past* the crossing, onto the branch
    that has just turned unstable, to bracket and refine it; the O(n) block Newton for large
    rings and rods), ``follow_twist`` the damped-Newton minimiser of ``relax``, guided by the
    predicted shape, which cannot wander onto an unstable branch. Analysis (shared): the
    stability, the tracked eigenpair with its derivative along the branch, and the new tangent.
    Acceptance: any converged state for ``critical_twist`` (it watches the negative count
    itself); for ``follow_twist`` a state that stayed within jump_tol of the prediction, has
    Lk = Lk0 + phi/2pi (closed rods) and no negative eigenvalue (after a soft-saddle escape)."""

    scene: object
    task: Task
    opts: ContinuationOptions
    sparse: bool = False

    @property
    def contact(self):
        return "contact" in self.scene.terms

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
        accept or refuse. index, ref, guess: the tracked eigenpair (see ``analyse``). Returns a
        _Step."""
        q_pred = prev.q + tangent * (phi - prev.phi)
        if self.task is Task.CRITICAL_TWIST:
            return self._newton_step(prev, q_pred, phi, index, ref, guess)
        return self._minimiser_step(prev, q_pred, phi)

    def _newton(self, phi, q_start, nbr):
        if self.sparse:
            return solve_equilibrium_sparse(self.scene, phi, q_start, gtol=self.opts.gtol, nbr=nbr)
        return solve_equilibrium(self.scene, phi, q_start, method="newton", with_stability=False,
                                 near_null_tol=self.opts.negative_tol if self.contact else 0.0,
                                 gtol=self.opts.gtol, nbr=nbr)

    def _newton_step(self, prev, q_pred, phi, index, ref, guess):
        try:
            e = self._newton(phi, q_pred, prev.neighbourhood)
        except ConvergenceError:
            try:  # from the last state itself, in case the predictor overshot
                e = self._newton(phi, prev.q, prev.neighbourhood)
            except ConvergenceError as exc:
                return _Step(None, refusal=_Refusal(StepFailure.NOT_CONVERGED, str(exc)))
        return self.analysed(e, index, ref, guess)

    def _minimiser_step(self, prev, q_pred, phi):
        opts = self.opts
        x_pred = np.asarray(self.scene.positions(jnp.asarray(q_pred)))
        try:
            e = relax(self.scene, phi, q_pred, gtol=opts.gtol, previous=prev, with_stability=False,
                      nbr=prev.neighbourhood, guide=(x_pred, opts.jump_tol), max_steps=opts.corrector_max_steps)
        except LeftBranchError as exc:
            return _Step(None, refusal=_Refusal(StepFailure.JUMP, str(exc)))
        except TopologyChangeError as exc:
            return _Step(None, refusal=_Refusal(StepFailure.TOPOLOGY, str(exc)))
        except ConvergenceError as exc:
            e = self._finish_stalled(exc, phi, prev)
            if e is None:
                return _Step(None, refusal=_Refusal(StepFailure.NOT_CONVERGED, str(exc)))
        moved = polyline_distance(e.x, x_pred, self.closed)
        if moved > opts.jump_tol:
            return _Step(e, refusal=_Refusal(StepFailure.JUMP, f"the state moved {moved:.3g} from the predicted shape"))
        s = self.analysed(e)
        if self.closed and abs(s.equilibrium.Lk - (self.lk0 + phi / (2.0 * math.pi))) > 1e-6:
            return replace(s, tangent=None,
                           refusal=_Refusal(StepFailure.LINKING, f"Lk = {s.equilibrium.Lk:.8f} is not Lk0 + phi/2pi"))
        if s.equilibrium.stability.n_negative > 0 and self.contact:
            # A soft, sliding-type mode of a loose knot may turn slightly negative: the minimiser
            # then stalls on a saddle that differs from a stable state only by a slide of the
            # material along the same shape. Push along the negative mode and relax: if a stable
            # state of the *same shape* appears, the branch goes on (no false detection).
            escaped = self._escape_soft_saddle(s.equilibrium, prev, x_pred)
            if escaped is not None:
                s = escaped
        n_negative = s.equilibrium.stability.n_negative
        if n_negative > 0:
            return replace(s, refusal=_Refusal(StepFailure.UNSTABLE, f"{n_negative} negative eigenvalue(s)"))
        return s

    def _finish_stalled(self, exc, phi, prev):
        """A minimiser that ran out of steps within a factor STALL_FACTOR of gtol has stalled on
        the near-null sliding modes of a contact knot (a curvature ~1e-8 makes its progress along
        them crawl), not met a fold (there it runs away from the prediction, or stops far from
        gtol). Finish it with Newton, which leaves the near-null directions alone; the result is
        checked like any corrected state (distance, Lk, stability). None if that fails too."""
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
                # Guided: a push along a real buckling mode runs off the predicted shape and is
                # stopped at its first pause instead of being relaxed to the end.
                e2 = relax(self.scene, e.phi, e.q + sgn * step, gtol=self.opts.gtol, previous=prev,
                           with_stability=False, nbr=e.neighbourhood, guide=(x_pred, jump_tol),
                           max_steps=self.opts.corrector_max_steps)
            except (ConvergenceError, TopologyChangeError):
                continue
            if polyline_distance(e2.x, x_pred, self.closed) > jump_tol:
                continue
            s = self.analysed(e2)
            if s.equilibrium.stability.n_negative == 0:
                return s
        return None


# "auto" takes the O(n) block path from this many DOFs on (N ~ 250 nodes): below it the dense
# path is fast enough, and compiled already for most small scenes.
_SPARSE_MIN_DOF = 1000

# Memory of the dense path, in bytes: DENSE_HESSIAN_COPIES * 8 n^2 + DENSE_BYTES_PER_DOF * n for n
# DOFs. The largest buffer is the compiled damped-Newton loop of ``relax`` (jaxrod.solvers: the
# Hessian, its symmetrised and shifted copies, an identity, the Cholesky factors of the shift
# search), allocated by XLA in one piece: its temporary buffer (``memory_analysis``) measured
# 6.78, 6.59, 6.48 n^2 doubles for the trefoil at N = 121, 242, 484 (n = 4N), i.e. 6.37 n^2 + 241 n
# doubles; that fit gives 81.55e9 bytes at N = 10000, where the allocation that failed (issue 16)
# was 81.66e9. The analysis (projected Hessian: 5 n^2 temporary + n^2 out; then LAPACK's copy)
# needs less; ``polyline_distance`` (~10 N^2 doubles) much less.
DENSE_HESSIAN_COPIES = 6.4
DENSE_BYTES_PER_DOF = 8 * 256
# The interpreter, the JAX/XLA runtime and the compiled code, besides the arrays.
PROCESS_BASE_BYTES = 1.0e9


def dense_memory_bytes(n_dof):
    """Bytes the dense linear algebra of a scene of ``n_dof`` DOFs needs at its peak (the
    damped-Newton corrector's n x n buffers; see DENSE_HESSIAN_COPIES)."""
    n = float(n_dof)
    return 8.0 * DENSE_HESSIAN_COPIES * n * n + DENSE_BYTES_PER_DOF * n


def available_memory_bytes():
    """Memory this process may still use, in bytes: MemAvailable of /proc/meminfo (Linux), else
    the physical memory (os.sysconf); a cgroup (container) limit, where lower, wins. None if
    unknown."""
    import os

    found = None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    found = float(line.split()[1]) * 1024.0
                    break
    except OSError:
        pass
    if found is None:
        try:
            found = float(os.sysconf("SC_PHYS_PAGES")) * float(os.sysconf("SC_PAGE_SIZE"))
        except (ValueError, OSError, AttributeError):
            pass
    cgroups = (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),  # v2, then v1
               ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"))
    for path, used_path in cgroups:
        try:
            with open(path) as f:
                limit = f.read().strip()
            if limit == "max" or float(limit) >= 2.0**60:
                continue
            with open(used_path) as f:
                left = float(limit) - float(f.read().strip())
            found = left if found is None else min(found, left)
        except (OSError, ValueError):
            continue
    return found


def check_dense_memory(scene, available=None):
    """Refuse (ValueError naming N, before anything is compiled) a scene whose dense Hessian does
    not fit in memory: ``dense_memory_bytes(scene.n_dof)`` plus PROCESS_BASE_BYTES against
    ``available`` bytes (default ``available_memory_bytes()``; nothing is checked when unknown).
    The message names the largest N that fits. scene: a scene, or any object with ``n_dof`` and
    ``n_nodes`` (to check before a long scene build). Returns the estimate in bytes."""
    need = dense_memory_bytes(scene.n_dof)
    avail = available_memory_bytes() if available is None else float(available)
    if avail is None or need + PROCESS_BASE_BYTES <= avail:
        return need
    n_nodes = int(scene.n_nodes)
    per_node = scene.n_dof / n_nodes
    # Largest n with 8 c n^2 + b n <= avail - base, then the nodes it allows.
    a, b, c = 8.0 * DENSE_HESSIAN_COPIES, float(DENSE_BYTES_PER_DOF), -(avail - PROCESS_BASE_BYTES)
    n_max = (-b + math.sqrt(max(b * b - 4.0 * a * c, 0.0))) / (2.0 * a) if c < 0.0 else 0.0
    n_nodes_max = int(math.floor(n_max / per_node))
    while n_nodes_max > 0 and dense_memory_bytes(math.ceil(per_node * n_nodes_max)) + PROCESS_BASE_BYTES > avail:
        n_nodes_max -= 1
    gb = lambda v: f"{v / 1e9:.0f} GB" if v >= 10e9 else f"{v / 1e9:.1f} GB"  # noqa: E731
    advice = f"use N at most {n_nodes_max}" if n_nodes_max > 0 else "no N fits"
    raise ValueError(
        f"N {n_nodes} needs about {gb(need)} of memory for the dense Hessian ({scene.n_dof} DOFs: the Newton "
        f"corrector holds ~{DENSE_HESSIAN_COPIES:g} copies of the {scene.n_dof} x {scene.n_dof} matrix); this machine "
        f"has {gb(avail)} available: {advice}")


def _use_sparse(scene, linear_algebra):
    """Whether ``critical_twist`` uses the block path (see its ``linear_algebra``)."""
    if linear_algebra not in ("auto", "dense", "sparse"):
        raise ValueError(f"linear_algebra must be 'auto', 'dense' or 'sparse', got {linear_algebra!r}")
    if linear_algebra == "sparse" and "contact" in scene.terms:
        raise ValueError("linear_algebra='sparse' does not handle self-contact: use 'dense'")
    if linear_algebra == "auto":
        return "contact" not in scene.terms and scene.n_dof >= _SPARSE_MIN_DOF
    return linear_algebra == "sparse"


K_MARGIN = EXTRA_PAIRS  # eigenpairs beyond the tracked index or the negative count (sparse path)


def _grown_engine(engine, needed):
    """``engine`` itself if its k eigenpairs reach index ``needed`` + K_MARGIN - 1 (needed: the
    tracked index or the negative count), else a copy with k = needed + K_MARGIN (sparse path
    only: the dense one computes LOWEST_COUNT eigenpairs whatever k)."""
    k = needed + K_MARGIN
    if not engine.sparse or k <= engine.opts.k or engine.opts.k >= engine.scene.n_dof:
        return engine
    return replace(engine, opts=replace(engine.opts, k=min(k, int(engine.scene.n_dof))))


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
    on_step=None,
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
    progress: optional callable(str) for progress lines; on_step: optional callable(phi,
    n_negative) after every equilibrium of the scan and the refinement (e.g. a progress bar).
    linear_algebra: "dense" (n x n Hessian, ``eigh``: O(n^3) per step), "sparse" (block-tridiagonal
    Newton, inertia, eigenpairs and tangent of ``jaxrod.sparse_branch``: O(n) per step; not with
    contact) or "auto" (sparse for scenes without contact with n_dof >= 1000, else dense). With
    "sparse" the stability's eigenvectors are the k lowest only, so the crossing mode must be
    among them: k grows (to the negative count or the tracked index plus K_MARGIN) where needed.
    The dense path refuses a scene whose n x n Hessian does not fit in memory
    (``check_dense_memory``, before anything is compiled). Returns a ``CriticalPoint``; raises
    ``NoCrossingError`` if the count never changes before phi_stop. Refuses knots (closed rods with
    self-contact: ``jaxrod.validation.refuse_knot`` says why and what to use instead).
    """
    t0 = time.perf_counter()
    phi_start = check_finite("phi_start", phi_start)
    phi_stop = check_finite("phi_stop", 8.0 * math.pi if phi_stop is None else phi_stop)
    if phi_stop == phi_start:
        raise ValueError("phi_stop must differ from phi_start")
    refuse_knot(scene, "critical_twist")
    opts = (options or ContinuationOptions()).updated(step=step, tol=tol, negative_tol=negative_tol, gtol=gtol, k=k)
    opts = opts.resolved(scene, Task.CRITICAL_TWIST, abs(phi_stop - phi_start))
    tol, negative_tol, gtol, k, max_step = opts.tol, opts.negative_tol, opts.gtol, opts.k, opts.step
    contact = "contact" in scene.terms
    direction = 1.0 if phi_stop > phi_start else -1.0
    min_step = max_step / 16.0
    say = progress or (lambda s: None)
    stepped = on_step or (lambda phi, n_negative: None)
    sparse = _use_sparse(scene, linear_algebra)
    if not sparse:
        check_dense_memory(scene)
    engine = _Engine(scene, Task.CRITICAL_TWIST, opts, sparse)
    k_scan = k  # eigenvalues kept per scan entry (the engine may compute more)

    if contact:
        relaxed = relax(scene, phi_start, q0, with_stability=False, gtol=gtol)
    elif sparse and scene.n_dof >= _SPARSE_MIN_DOF:
        # Large n: no dense relaxation (O(n^3) per step); Newton from q0 (for rings and straight
        # clamped rods the initial shape already is the equilibrium, up to the twist angles).
        relaxed = solve_equilibrium_sparse(scene, phi_start, q0, gtol=gtol)
    else:
        relaxed = solve_equilibrium(scene, phi_start, q0, method="auto", with_stability=False, gtol=gtol)
    start = engine.analysed(relaxed)
    while True:
        count0 = int(start.equilibrium.stability.n_negative)
        # The eigenvalue that crosses next: the lowest one clearly above zero (near-zero modes skipped).
        ev0 = start.equilibrium.stability.eigenvalues
        index = int(np.sum(ev0 < negative_tol)) if ev0.size else 0
        grown = _grown_engine(engine, max(index, count0))
        if grown is engine:
            break
        engine, start = grown, grown.analysed(relaxed)
    if index != 0:
        start = engine.analysed(relaxed, index)
    prev, dq, lam_t, dlam_t = start.equilibrium, start.tangent, start.eigenvalue, start.dlambda_dphi
    scan = [(prev.phi, count0, prev.stability.eigenvalues[:k_scan].copy())]
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
        s = engine.step(prev, dq, phi_next, index,
                        guess=min(prev.stability.eigenvalues[0], lam_t + dlam_t * (phi_next - prev.phi)))
        if not s.ok:
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
        cur = s.equilibrium
        grown = _grown_engine(engine, int(cur.stability.n_negative))
        if grown is not engine:  # the crossing mode must be among the eigenpairs computed at cur
            engine = grown
            s = engine.analysed(cur, index, guess=cur.stability.eigenvalues[0])
            cur = s.equilibrium
        stepped(cur.phi, int(cur.stability.n_negative))
        scan.append((cur.phi, cur.stability.n_negative, cur.stability.eigenvalues[:k_scan].copy()))
        say(
            f"phi = {cur.phi / math.pi:+.4f} pi: {cur.stability.n_negative} negative, "
            f"lowest {cur.stability.eigenvalues[:3]}"
        )
        if cur.stability.n_negative != count0:
            break
        # Newton-extrapolated crossing of the tracked eigenvalue: aim 10% past it.
        h = max_step
        if s.dlambda_dphi != 0.0:
            ahead = -s.eigenvalue / s.dlambda_dphi * direction
            if ahead > 0.0:
                h = min(max_step, max(min_step, 1.1 * ahead))
        before, prev, dq, lam_t, dlam_t = prev, cur, s.tangent, s.eigenvalue, s.dlambda_dphi

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
    _, f_hi, _, v_hi, _ = engine.analyse(hi, idx_hi, ref=ref, guess=hi.stability.eigenvalues[0])
    _, f_lo, d_lo, v_lo, dq_lo = engine.analyse(lo, ref=v_hi, guess=lo.stability.eigenvalues[0])
    if np.sign(f_lo) == np.sign(f_hi) and before is not None:
        # The crossing eigenvalue already changed sign at lo but stayed inside the near-zero band
        # (|lambda| < negative_tol, e.g. a soft ring of N ~ 1000, lambda ~ 1e-9): the count missed
        # it there. Take the scan state before as the stable end, so that the bracket holds a sign
        # change (the sign tests below rely on it).
        lo, evals = before, 3
        _, f_lo, d_lo, v_lo, dq_lo = engine.analyse(lo, ref=v_hi, guess=lo.stability.eigenvalues[0])
    if np.sign(f_lo) == np.sign(f_hi):
        # No sign change of the crossing eigenvalue in the bracket: a refinement would converge
        # on a bracket end and report it as phi* (seen: 6.27 pi for 5.20 pi, N = 2000 ring with
        # a fixed negative_tol = 1e-10 far above its eigenvalues).
        raise ConvergenceError(
            f"critical twist: the crossing eigenvalue has the same sign ({f_lo:.3e}, {f_hi:.3e}) at both ends "
            f"of the bracket [{lo.phi:.8g}, {hi.phi:.8g}] where the negative count changed: negative_tol = "
            f"{negative_tol:.3g} is not small against the eigenvalues")
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
        s = engine.step(base, base_dq, phi_c, ref=v_ref,
                        guess=min(base.stability.eigenvalues[0], f_base + d_base * (phi_c - base.phi)))
        if not s.ok:
            raise ConvergenceError(f"critical twist refinement: no equilibrium at phi = {phi_c:.10g} "
                                   f"({s.refusal.detail})")
        e, f_c, d_c, v_c, dq_c = s.equilibrium, s.eigenvalue, s.dlambda_dphi, s.mode, s.tangent
        stepped(e.phi, int(e.stability.n_negative))
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

    phi: estimate, inside the bracket (the critical eigenvalue extrapolated from the last stable
    state, see ``_locate``); phi_error: its distance to the bracket's far end (so the whole
    bracket lies within phi +- phi_error); bracket: (last stable twist reached, nearest twist
    where the branch was lost, or where its critical eigenvalue was found negative); kind: 'unstable' (the corrector
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


class Phase(_ValueEnum):
    """Where a ``follow_twist`` run stands (``PathState.phase``)."""

    FOLLOW = "follow"  # stepping along the branch
    LOCATE = "locate"  # the branch was lost: shrinking the bracket around its end to tol
    CONFIRM = "confirm"  # the nearest failure was met from further back: retry it from the last state
    END = "end"  # the end is bracketed: locate phi*, then switch branches or stop
    DONE = "done"


@dataclass(frozen=True)
class PathState:
    """Everything a ``follow_twist`` run needs to go on, between two corrector calls.

    ``follow_twist(..., on_state=f)`` calls f(state) after every step tried (and after the
    points and instabilities that step reported); ``follow_twist(..., resume=state)`` goes on
    from it exactly as the uninterrupted run would (the continuation is deterministic: a
    resumed run reports the same points and instabilities, to the last bit). ``to_arrays()``
    and ``PathState.from_arrays(scene, arrays)`` store it in an npz file (every equilibrium by
    its scaled DOFs, solver record and neighbourhood; the stabilities are recomputed on load).

    phase: a ``Phase``; branch: name of the branch followed ('symmetric+', ...); prev: last
    stable state (with stability), tangent: dq/dphi there; older: the state before it (or None);
    h: current step; switches: branch switches made; n_points / n_instabilities: reported so far
    (a study keeps as many rows and instabilities on file); lost_*: the nearest twist where the
    branch was lost, the refusal there and its state, and from which twist it was tried;
    failures / successes / probe_held: the end locator's memory (see ``_end_trial``);
    stop / reason: why the run stopped (phase DONE); critical_modes: (n, m) eigenvectors (scaled
    DOFs) of the eigenvalues below -negative_tol where the branch was lost unstable (None
    otherwise): while the end is located, a state whose eigenvalue along them is negative, even
    inside the near-zero band, is past the end (``_past_zero``).
    """

    phase: Phase
    branch: str
    prev: Equilibrium = field(repr=False)
    tangent: np.ndarray = field(repr=False)
    older: Equilibrium | None = field(default=None, repr=False)
    h: float = 0.0
    switches: int = 0
    n_points: int = 0
    n_instabilities: int = 0
    lost_phi: float = math.nan
    lost_from: float = math.nan
    lost_refusal: _Refusal | None = None
    lost_equilibrium: Equilibrium | None = field(default=None, repr=False)
    failures: int = 0
    successes: int = 0
    probe_held: bool = False
    stop: PathStop | None = None
    reason: str = ""
    critical_modes: np.ndarray | None = field(default=None, repr=False)

    def to_arrays(self):
        """The state as a dict of numpy arrays (for ``np.savez``)."""
        out = {"phase": np.asarray(self.phase.value), "branch": np.asarray(self.branch), "h": np.asarray(self.h)}
        for key in ("switches", "n_points", "n_instabilities", "failures", "successes"):
            out[key] = np.asarray(getattr(self, key), dtype=np.int64)
        out.update(lost_phi=np.asarray(self.lost_phi), lost_from=np.asarray(self.lost_from),
                   probe_held=np.asarray(self.probe_held), stop=np.asarray("" if self.stop is None else self.stop.value),
                   reason=np.asarray(self.reason))
        if self.lost_refusal is not None:
            out["lost_failure"] = np.asarray(self.lost_refusal.failure.value)
            out["lost_detail"] = np.asarray(self.lost_refusal.detail)
        if self.critical_modes is not None:
            out["critical_modes"] = np.asarray(self.critical_modes)
        for name in ("prev", "older", "lost_equilibrium"):
            e = getattr(self, name)
            if e is not None:
                out.update(equilibrium_arrays(e, name + "_"))
                out[name + "_analysed"] = np.asarray(e.stability is not None)
        return out

    @classmethod
    def from_arrays(cls, arrays):
        """A state from ``to_arrays``'s dict (or an opened npz), with its equilibria still to be
        rebuilt: ``follow_twist(resume=...)`` does that (it knows the scene and the options)."""
        return _StoredPathState(dict(arrays))


@dataclass(frozen=True)
class _StoredPathState:
    """A ``PathState`` as loaded from a file: arrays, equilibria not yet rebuilt."""

    arrays: dict

    def restore(self, engine):
        a = self.arrays

        def equilibrium(name):
            if name + "_y" not in a:
                return None, None
            e = equilibrium_from_arrays(engine.scene, a, name + "_")
            if not bool(a[name + "_analysed"]):
                return e, None
            s = engine.analysed(e)
            return s.equilibrium, s.tangent

        prev, tangent = equilibrium("prev")
        older, _ = equilibrium("older")
        lost, _ = equilibrium("lost_equilibrium")
        refusal = None
        if "lost_failure" in a:
            refusal = _Refusal(StepFailure(str(a["lost_failure"])), str(a["lost_detail"]))
        stop = str(a["stop"])
        return PathState(
            phase=Phase(str(a["phase"])), branch=str(a["branch"]), prev=prev, tangent=tangent, older=older,
            h=float(a["h"]), switches=int(a["switches"]), n_points=int(a["n_points"]),
            n_instabilities=int(a["n_instabilities"]), lost_phi=float(a["lost_phi"]), lost_from=float(a["lost_from"]),
            lost_refusal=refusal, lost_equilibrium=lost, failures=int(a["failures"]), successes=int(a["successes"]),
            probe_held=bool(a["probe_held"]), stop=PathStop(stop) if stop else None, reason=str(a["reason"]),
            critical_modes=np.asarray(a["critical_modes"]) if "critical_modes" in a else None,
        )


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
    on_state=None,
    resume=None,
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
    -negative_tol (see ``_Engine``). Otherwise the step is halved; once the failing twist is
    within ``tol`` of the last accepted one, the branch has ended there (a failure that persists
    as the step goes to zero is not a step-size artefact). Near-zero modes (|lambda| <
    negative_tol: strands sliding in a loose knot, ~1e-7) never count.

    Branch switching: at the nearest twist where the branch was lost, the predicted state is
    pushed by +-``perturbation`` (default D/2 at the node that moves most) along the critical
    eigenvector and relaxed; the lower-energy stable state away from the old branch is the new
    branch ("buckled", then "buckled2", ...; the sign of the direction is appended).

    Tolerances (step, tol, negative_tol, gtol, jump_tol, k): keywords or an ``options``
    (``ContinuationOptions``, where their scene-aware defaults are defined; a keyword that is not
    None wins). scene: closed or clamped rod scene; q0 or start (an Equilibrium to begin from,
    used as is); step: largest step in phi (default 0.25 pi); on_point(BranchPoint) and
    progress(str): callbacks (e.g. to write rows as they come); on_instability(Instability):
    called as soon as a branch end is located (and, after a switch, before the new branch's
    first point), so that a study can keep it on file at once. on_state(PathState): called after
    every step tried; resume: a ``PathState`` (or ``PathState.from_arrays``) to go on from, in
    place of phi_start / q0 / start / branch (the same scene, phi_stop and tolerances must be
    given). The run is deterministic, so a resumed run reports exactly the points and
    instabilities that the uninterrupted one reports after that state. Returns a ``TwistPath``
    (with the points and instabilities of this call). A scene whose dense n x n Hessian does not
    fit in memory is refused at once (``check_dense_memory``: ValueError naming N).
    """
    t0 = time.perf_counter()
    phi_stop = check_finite("phi_stop", 8.0 * math.pi if phi_stop is None else phi_stop)
    check_dense_memory(scene)  # follow_twist is dense: refuse before anything is compiled
    opts = (options or ContinuationOptions()).updated(step=step, tol=tol, negative_tol=negative_tol, gtol=gtol,
                                                      jump_tol=jump_tol, k=k)
    points, instabilities = [], []
    say = progress or (lambda s: None)
    warned = set()  # branches already warned about a shape mode inside the near-zero band

    def emit(state, s):
        e = s.equilibrium
        point = BranchPoint(branch=state.branch, equilibrium=e, tangent=s.tangent, scene=scene)
        points.append(point)
        if on_point is not None:
            on_point(point)
        lam = e.stability.eigenvalues
        say(f"[{state.branch}] phi = {e.phi / math.pi:+.5f} pi: E = {e.energy:.6g}, Wr = {e.Wr:.4f}, "
            f"Tw = {e.Tw:.4f}, {e.stability.n_negative} negative, lowest " + " ".join(f"{v:.2e}" for v in lam[:3]))
        _warn_if_band_hides_shape_modes(scene, state.branch, e, opts, warned)  # opts resolved below, before any step
        return replace(state, n_points=state.n_points + 1)

    def record(state, inst):
        instabilities.append(inst)
        if on_instability is not None:
            on_instability(inst)
        return replace(state, n_instabilities=state.n_instabilities + 1)

    if resume is not None:
        # The direction is the branch name's sign; the span only sizes the default step, which
        # the resumed run must share with the first one (pass the same phi_stop).
        stored_phi = float(resume.arrays["prev_phi"]) if isinstance(resume, _StoredPathState) else resume.prev.phi
        opts = opts.resolved(scene, Task.FOLLOW_TWIST, abs(phi_stop - stored_phi) or 1.0)
        engine = _Engine(scene, Task.FOLLOW_TWIST, opts)
        state = resume.restore(engine) if isinstance(resume, _StoredPathState) else resume
        direction = 1.0 if state.branch.endswith("+") else -1.0
    else:
        phi_start = check_finite("phi_start", phi_start if start is None else start.phi)
        if phi_stop == phi_start:
            raise ValueError("phi_stop must differ from phi_start")
        direction = 1.0 if phi_stop > phi_start else -1.0
        opts = opts.resolved(scene, Task.FOLLOW_TWIST, abs(phi_stop - phi_start))
        engine = _Engine(scene, Task.FOLLOW_TWIST, opts)
        if start is None:
            e0 = relax(scene, phi_start, q0, gtol=opts.gtol, with_stability=False)
        else:
            e0 = start
            if e0.neighbourhood is None:
                e0 = replace(e0, neighbourhood=scene.neighbourhood(e0.q, e0.phi))
        s = engine.analysed(e0)
        if s.equilibrium.stability.n_negative:
            st = s.equilibrium.stability
            raise ValueError(
                f"the starting state at phi = {e0.phi:.6g} is unstable ({st.n_negative} negative eigenvalue(s), "
                f"lowest {st.eigenvalues[0]:.3e}): follow_twist follows a stable branch; start from a minimum "
                "(jaxrod.relax_to_minimum)")
        state = PathState(phase=Phase.FOLLOW, branch=f"{branch}{'+' if direction > 0 else '-'}",
                          prev=s.equilibrium, tangent=s.tangent, h=opts.step)
        state = emit(state, s)
        if on_state is not None:
            on_state(state)
    follower = _Follower(engine, phi_stop, direction, switch, max_switches, perturbation, emit, record, say)
    while state.phase is not Phase.DONE:
        state = follower.advance(state)
        if on_state is not None:
            on_state(state)
    return TwistPath(points=points, instabilities=instabilities, reason=state.reason,
                     seconds=time.perf_counter() - t0, stop=state.stop)


@dataclass(frozen=True)
class _Follower:
    """``follow_twist``'s loop body: ``advance(state)`` tries one step (or, at a located end,
    switches branches) and returns the next ``PathState``."""

    engine: _Engine
    phi_stop: float
    direction: float
    switch: bool
    max_switches: int
    perturbation: float | None
    emit: object
    record: object
    say: object

    def advance(self, state):
        return {Phase.FOLLOW: self._follow, Phase.LOCATE: self._locate, Phase.CONFIRM: self._confirm,
                Phase.END: self._end}[state.phase](state)

    def _accept(self, state, s, **changes):
        state = replace(state, older=state.prev, prev=s.equilibrium, tangent=s.tangent, **changes)
        return self.emit(state, s)

    def _follow(self, state):
        prev, step, direction = state.prev, self.engine.opts.step, self.direction
        if direction * (self.phi_stop - prev.phi) <= 1e-12:
            return replace(state, phase=Phase.DONE, stop=PathStop.PHI_STOP, reason="phi_stop")
        # Steps land on the grid of multiples of ``step`` (so whole turns are visited, where the
        # ribbon closes and the Gauss linking number can be compared) unless shortened.
        grid = step * (math.floor(prev.phi / step + 1e-9) + 1 if direction > 0 else math.ceil(prev.phi / step - 1e-9) - 1)
        phi_next = prev.phi + direction * min(state.h, abs(self.phi_stop - prev.phi), abs(grid - prev.phi))
        s = self.engine.step(prev, state.tangent, phi_next)
        hidden = _hidden_shape_modes(self.engine, s.equilibrium) if s.ok else None
        if s.ok and hidden is None:
            return self._accept(state, s, h=min(step, 2.0 * state.h))
        if hidden is not None:
            # Converged, every eigenvalue above -negative_tol, but a mode that changes the shape
            # (not material sliding) is negative inside the near-zero band kept for the sliding
            # modes: the branch has ended (issue 17: at N = 241 and 481 the trefoil's opening side
            # was called stable 0.09 pi and 1.09 pi past its end). Refused as unstable, with that
            # mode as the critical one, so the locator below tracks its eigenvalue's sign.
            s = replace(s, refusal=_hidden_refusal(hidden[0]))
        # The branch was lost at phi_next: shrink the bracket between the last stable state and
        # there to tol, aiming each trial with a model of the critical eigenvalue (a few solves
        # where bisection needs ~log2(step/tol) ~ 11).
        self.say(f"[{state.branch}] lost at phi = {phi_next / math.pi:+.5f} pi ({s.refusal}); locating the end")
        critical = hidden[1] if hidden is not None else self._critical_modes(s, None)
        lam = _past_zero(critical, prev)
        if lam is not None and state.older is not None and _past_zero(critical, state.older) is None:
            # The last accepted state already has the critical eigenvalue below zero (inside the
            # near-zero band, so the stability test let it pass): the end lies between the state
            # before it and it. Locate it there, from the state before.
            self.say(f"[{state.branch}] phi = {prev.phi / math.pi:+.5f} pi is past the end already (critical "
                     f"eigenvalue {lam:.3e}); locating it from phi = {state.older.phi / math.pi:+.5f} pi")
            back = self.engine.analysed(state.older)
            return replace(state, phase=Phase.LOCATE, prev=back.equilibrium, tangent=back.tangent, older=None,
                           lost_phi=prev.phi, lost_refusal=_Refusal(StepFailure.UNSTABLE, _band_detail(lam)),
                           lost_equilibrium=prev, lost_from=state.older.phi, failures=0, successes=0,
                           probe_held=False, critical_modes=critical)
        return replace(state, phase=Phase.LOCATE, lost_phi=phi_next, lost_refusal=s.refusal,
                       lost_equilibrium=s.equilibrium, lost_from=prev.phi, failures=0, successes=0, probe_held=False,
                       critical_modes=critical)

    def _critical_modes(self, s, current):
        """The critical modes for ``PathState.critical_modes`` after the refused step s: the
        eigenvectors of its eigenvalues below -negative_tol where it converged unstable (or, none
        being there, of its shape modes negative inside the near-zero band), else ``current``."""
        if s.refusal is None or s.refusal.failure is not StepFailure.UNSTABLE:
            return current
        found = _negative_modes(s.equilibrium, self.engine.opts.negative_tol)
        if found is None:
            hidden = _hidden_shape_modes(self.engine, s.equilibrium)
            found = None if hidden is None else hidden[1]
        return current if found is None else found

    def _unless_past_zero(self, state, s):
        """The accepted step s, or s refused (UNSTABLE) when its critical eigenvalue is already
        negative (see ``PathState.critical_modes``), or when a shape mode is negative inside the
        near-zero band (``_hidden_shape_modes``)."""
        if not s.ok:
            return s
        lam = _past_zero(state.critical_modes, s.equilibrium)
        if lam is not None:
            return replace(s, refusal=_Refusal(StepFailure.UNSTABLE, _band_detail(lam)))
        hidden = _hidden_shape_modes(self.engine, s.equilibrium)
        if hidden is not None:
            return replace(s, refusal=_hidden_refusal(hidden[0]))
        return s

    def _locate(self, state):
        tol, prev = self.engine.opts.tol, state.prev
        if abs(state.lost_phi - prev.phi) <= tol:
            # Bracketed. If the nearest failure was met from a state further back, confirm it from
            # the last stable state, so that a predictor too far off is not taken for the end.
            return replace(state, phase=Phase.CONFIRM if abs(state.lost_phi - state.lost_from) > tol else Phase.END)
        trial, probe = _end_trial(state.older, prev, state.lost_phi, state.lost_equilibrium, self.direction, tol,
                                  self.engine.opts.negative_tol, state.failures, state.probe_held, state.successes,
                                  state.critical_modes)
        s = self._unless_past_zero(state, self.engine.step(prev, state.tangent, trial))
        if s.ok:
            return self._accept(state, s, failures=0, successes=state.successes + 1, probe_held=probe)
        self.say(f"[{state.branch}] phi = {trial / math.pi:+.5f} pi refused ({s.refusal})")
        return replace(state, lost_phi=trial, lost_refusal=s.refusal, lost_equilibrium=s.equilibrium,
                       lost_from=prev.phi, failures=state.failures + 1, successes=0, probe_held=False,
                       critical_modes=self._critical_modes(s, state.critical_modes))

    def _confirm(self, state):
        s = self._unless_past_zero(state, self.engine.step(state.prev, state.tangent, state.lost_phi))
        if not s.ok:
            return replace(state, phase=Phase.END, lost_refusal=s.refusal, lost_equilibrium=s.equilibrium)
        self.say(f"[{state.branch}] phi = {state.lost_phi / math.pi:+.5f} pi reached from closer by: going on")
        # The step that failed was too long for the predictor, not past the end: go on with half
        # of it (not from 2 tol, which needs ~10 doublings back to ``step``).
        h = max(2.0 * self.engine.opts.tol, 0.5 * abs(state.lost_phi - state.lost_from))
        return self._accept(state, s, phase=Phase.FOLLOW, h=h, critical_modes=None)

    def _end(self, state):
        engine, prev, direction, lost_phi = self.engine, state.prev, self.direction, state.lost_phi
        kind = BranchEnd.UNSTABLE if state.lost_refusal.failure is StepFailure.UNSTABLE else BranchEnd.JUMP
        inst = _critical_mode(engine, prev, state.older, kind, direction)
        rate = inst.dlambda_dphi if kind is BranchEnd.UNSTABLE or not math.isfinite(inst.dlambda_dphi_secant) \
            else inst.dlambda_dphi_secant
        phi_c, phi_err = _locate(prev.phi, lost_phi, inst.eigenvalue, rate, direction)
        inst = replace(inst, phi=phi_c, phi_error=phi_err, bracket=(prev.phi, lost_phi), from_branch=state.branch,
                       negative_tol=engine.opts.negative_tol)
        self.say(f"[{state.branch}] branch ends at phi* = {inst.phi / math.pi:+.6f} pi +- {inst.phi_error:.1e} rad "
                 f"({kind}; last: {state.lost_refusal}); critical eigenvalue {inst.eigenvalue:.3e}, "
                 f"d/dphi {inst.dlambda_dphi:.3e}")
        if not self.switch or state.switches >= self.max_switches:
            state = self.record(state, inst)
            return replace(state, phase=Phase.DONE, stop=PathStop.BRANCH_ENDED,
                           reason=f"branch ended at phi = {inst.phi:.8g} ({kind})")
        found = _switch_branch(engine, prev, state.tangent, lost_phi, inst.mode, state.lost_equilibrium,
                               self.perturbation, self.say)
        if found is None:
            state = self.record(replace(state, switches=state.switches + 1), inst)
            return replace(state, phase=Phase.DONE, stop=PathStop.NO_STABLE_BRANCH,
                           reason=f"no stable branch found beyond phi = {lost_phi:.8g}")
        new_name = _next_branch_name(state.branch[:-1]) + state.branch[-1]
        state = self.record(state, replace(inst, to_branch=new_name, jumped_to=found.equilibrium))
        state = replace(state, phase=Phase.FOLLOW, branch=new_name, prev=found.equilibrium, tangent=found.tangent,
                        older=None, h=engine.opts.step, switches=state.switches + 1, lost_phi=math.nan,
                        lost_from=math.nan, lost_refusal=None, lost_equilibrium=None, failures=0, successes=0,
                        probe_held=False, critical_modes=None)
        # The new branch's first point, after its instability (a study then has both on file).
        return self.emit(state, found)


# A state's eigenvector belongs to the critical modes when its projection on them has at least
# this norm (the overlap the end locator uses to match eigenvectors between states).
_CRITICAL_OVERLAP = 0.5


def _warn_if_band_hides_shape_modes(scene, branch, e, opts, warned):
    """Warn (once per branch) when a state reported stable has a negative eigenvalue inside the
    near-zero band whose mode changes the shape instead of sliding material along the knot
    (``stability.shape_modes_in_band``): the band, there for sliding modes, may hide a real
    instability, and the branch may have ended before this state."""
    if branch in warned or not opts.negative_tol > DEFAULT_NEGATIVE_TOL:
        return
    hidden = shape_modes_in_band(scene, e, opts.negative_tol)
    if hidden:
        warned.add(branch)
        lam, frac = hidden[0]
        warnings.warn(
            f"{branch} at phi = {e.phi / math.pi:+.5f} pi is reported stable, but {len(hidden)} mode(s) that change "
            f"the shape (not material sliding: sliding fraction {frac:.2f}) have negative eigenvalues inside the "
            f"near-zero band kept for sliding modes (lowest {lam:.2e} > -{opts.negative_tol:.0e}): the branch may "
            "have ended before here, unnoticed", stacklevel=4)


def _hidden_refusal(lam):
    return _Refusal(StepFailure.UNSTABLE, f"a shape mode's eigenvalue {lam:.3e} < 0 inside the near-zero band kept "
                                          "for sliding modes")


def _hidden_shape_modes(engine, e):
    """(lowest eigenvalue, eigenvectors (n, m)) of the equilibrium e's modes that change the
    shape and are negative inside the near-zero band (``stability.shape_modes_in_band``), or None
    (no such mode, no band, no state or stability, or a scene without contact)."""
    if e is None or e.stability is None or not engine.contact or not engine.opts.negative_tol > DEFAULT_NEGATIVE_TOL:
        return None
    hidden = shape_modes_in_band(engine.scene, e, engine.opts.negative_tol)
    if not hidden:
        return None
    lam = np.asarray(e.stability.eigenvalues)
    wanted = {v for v, _ in hidden}
    cols = [j for j in range(lam.size) if float(lam[j]) in wanted]
    return min(wanted), np.asarray(e.stability.eigenvectors)[:, cols].copy()


def _negative_modes(e, negative_tol):
    """(n, m) eigenvectors of the equilibrium e's eigenvalues below -negative_tol (the modes that
    made it unstable), or None."""
    if e is None or e.stability is None:
        return None
    st = e.stability
    neg = np.asarray(st.eigenvalues) < -negative_tol
    if not np.any(neg):
        return None
    return np.asarray(st.eigenvectors)[:, neg].copy()


def _past_zero(critical_modes, e):
    """The eigenvalue of the equilibrium e that is negative along ``critical_modes`` ((n, m), or
    None), or None: e is then past the zero of the critical eigenvalue, though the stability test
    (lambda < -negative_tol) passed it. The near-zero band is there for the sliding modes of a
    loose knot (|lambda| ~ 1e-7, changing sign from step to step); the mode that made the branch
    unstable is not one of them, and where it crosses zero is where the branch ends (issue 16:
    a critical eigenvalue of slope -1.2e-5 per rad passes -1e-6 only 0.085 rad after zero)."""
    if critical_modes is None or e is None or e.stability is None:
        return None
    st = e.stability
    lam, vec = np.asarray(st.eigenvalues), np.asarray(st.eigenvectors)
    for j in np.nonzero(lam < 0.0)[0]:
        if np.linalg.norm(critical_modes.T @ vec[:, j]) > _CRITICAL_OVERLAP:
            return float(lam[j])
    return None


def _band_detail(lam):
    return f"the critical eigenvalue is {lam:.3e} < 0 (inside the near-zero band)"


def _critical_candidates(older, prev, negative_tol, candidates=5, critical_modes=None):
    """(lambda_prev, lambda_older, eigenvector) of the lowest eigen-modes of ``prev`` above the
    near-zero band (or inside it, when along ``critical_modes``: the mode that made the branch
    unstable, about to cross zero), each matched in ``older`` by eigenvector overlap (no new
    spectrum needed)."""
    st, so = prev.stability, older.stability
    if st is None or so is None:
        return []
    out = []
    for j in range(min(candidates, len(st.eigenvalues))):
        lam = float(st.eigenvalues[j])
        if abs(lam) <= negative_tol and (critical_modes is None or np.linalg.norm(
                critical_modes.T @ np.asarray(st.eigenvectors[:, j])) <= _CRITICAL_OVERLAP):
            continue
        v = np.asarray(st.eigenvectors[:, j])
        ov = np.abs(np.asarray(so.eigenvectors).T @ v)
        out.append((lam, float(so.eigenvalues[int(np.argmax(ov))]), v))
    return out


def _end_trial(older, prev, phi_lost, lost_eq, direction, tol, negative_tol, failures, probe_held, successes=0,
               critical_modes=None):
    """The next twist to try when locating where a branch ends, between the last stable state
    ``prev`` and the nearest twist ``phi_lost`` where the branch was lost. Returns (phi, probe).

    Model: near a fold the critical eigenvalue goes like sqrt(phi* - phi), so lambda^2 is linear
    in phi; its secant through ``older`` and ``prev`` (the mode that reaches zero first) gives
    phi*, never beyond it at a transversal crossing (where it lands short). When the lost state
    is an equilibrium with a negative critical eigenvalue (a crossing), lambda is interpolated
    linearly between the two ends instead, to its zero (``critical_modes``: the modes that made
    the branch unstable, whose eigenvalue is a candidate even inside the near-zero band). The
    trial aims 0.3 tol short of phi*, or, when the stable end is already there, probes 0.9 tol
    beyond it (probe = True), so that a good model closes the bracket to tol in two solves. Safeguards: bisection when there is no model, after two
    failures or two successes in a row (a model that keeps landing short converges on a point
    that is not the end: the stable end would creep towards it), after a probe that held, or
    when the model lands outside the inner 90% of the bracket."""
    width = direction * (phi_lost - prev.phi)
    mid = prev.phi + 0.5 * direction * width
    if failures >= 2 or successes >= 2 or probe_held or older is None or older.phi == prev.phi:
        return mid, False
    estimates = []
    for lam, lam_old, v in _critical_candidates(older, prev, negative_tol, critical_modes=critical_modes):
        if lam <= 0.0:
            continue
        if lost_eq is not None and lost_eq.stability is not None:
            ov = np.abs(np.asarray(lost_eq.stability.eigenvectors).T @ v)
            lam_lost = float(lost_eq.stability.eigenvalues[int(np.argmax(ov))])
            if lam_lost < 0.0 and ov.max() > _CRITICAL_OVERLAP:
                # The branch is lost where lambda passes zero: a state whose critical eigenvalue
                # is negative, even inside the near-zero band, is past the end (``_past_zero``).
                estimates.append(prev.phi + (phi_lost - prev.phi) * lam / (lam - lam_lost))
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
    """(phi*, error) for a branch end bracketed by the last stable twist ``phi_stable`` and the
    nearest twist ``phi_lost`` where the branch was lost: the critical eigenvalue's Newton
    extrapolation phi_stable - lam/dlam from the stable end where it lands inside the bracket (at
    a crossing it is exact to second order; at a fold, where lambda goes like a square root, it
    lands short, inside), otherwise the bracket's midpoint. The end lies in the bracket, so the
    error bound is the distance from phi* to the bracket's far end (half the bracket at the
    midpoint). (An extrapolation behind the stable end, from a critical eigenvalue already
    negative there, used to be taken up to 0.1 pi back: issue 16, phi* 0.085 rad before a bracket
    of 4e-4 rad. The end locator now keeps such states out of the stable end: ``_past_zero``.)"""
    a, b = sorted((phi_stable, phi_lost))
    mid = 0.5 * (a + b)
    phi = mid
    if dlam != 0.0 and math.isfinite(dlam) and math.isfinite(lam):
        newton = phi_stable - lam / dlam
        if a <= newton <= b:
            phi = newton
    return phi, max(phi - a, b - phi)


def _next_branch_name(name):
    """symmetric -> buckled -> buckled2 -> buckled3 ..."""
    if not name.startswith("buckled"):
        return "buckled"
    tail = name[len("buckled"):]
    return f"buckled{int(tail) + 1 if tail.isdigit() else 2}"


def _critical_mode(engine, prev, older, kind, direction, candidates=5):
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
        _, lam_j, dlam_j, v_j, _ = engine.analyse(prev, j)
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


def _switch_branch(engine, prev, dq, phi, mode, lost_eq, perturbation, say):
    """Relax from the predicted state pushed both ways along the critical mode (and from the
    state the corrector itself jumped to, if any); keep stable states away from the old branch
    with the right Lk; return the lowest in energy as an analysed _Step, or None."""
    scene, closed, jump_tol = engine.scene, engine.closed, engine.opts.jump_tol
    q_pred = prev.q + dq * (phi - prev.phi)
    x_pred = np.asarray(scene.unpack(jnp.asarray(q_pred), phi)[0])
    step = mode_step(scene, mode, jump_tol if perturbation is None else float(perturbation))
    starts = [("+mode", q_pred + step), ("-mode", q_pred - step)]
    # Where the corrector itself goes when left alone (it was stopped early while locating the
    # end, so that state is computed here, once).
    starts.append(("jumped", np.asarray(lost_eq.q) if lost_eq is not None else q_pred))
    best = None
    for label, q_start in starts:
        try:
            e = relax(scene, phi, q_start, gtol=engine.opts.gtol, previous=prev, with_stability=False,
                      nbr=prev.neighbourhood)
        except (ConvergenceError, TopologyChangeError) as exc:
            say(f"  switch from {label}: {type(exc).__name__}: {exc}")
            continue
        moved = polyline_distance(e.x, x_pred, closed)
        s = engine.analysed(e)
        e = s.equilibrium
        lk_ok = (not closed) or abs(e.Lk - (engine.lk0 + phi / (2.0 * math.pi))) <= 1e-6
        say(f"  switch from {label}: E = {e.energy:.8g}, Wr = {e.Wr:.4f}, moved {moved:.3g}, "
            f"{e.stability.n_negative} negative, Lk ok: {lk_ok}")
        if moved <= jump_tol or not e.stability.stable or not lk_ok:
            continue
        if best is None or e.energy < best.equilibrium.energy:
            best = s
    return best
