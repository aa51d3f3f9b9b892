"""How a stable-only continuation runs: ``ContinuationOptions`` (every tolerance, budget and
behaviour knob, None meaning the scene-aware default that ``resolved`` fills in), ``Task`` (which
entry the defaults are for) and ``Observer`` (the callbacks: progress lines, points, states)."""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, fields, replace

from ..linalg.stability import CONTACT_NEGATIVE_TOL
from ..linalg.tolerances import NEGATIVE_TOL_FRACTION, scaled_negative_tol  # noqa: F401  (re-exported)
from ..validation import check_int_at_least, check_positive

# Damped-Newton iterations a continuation corrector may take between two neighbourhood pauses.
# From the tangent predictor a step converges in 2-15; one still crawling after 60 is not near
# its branch (seen: 500 iterations, 9 s, on a trefoil past its fold) and the step is refused.
CORRECTOR_MAX_STEPS = 60
# The corrector's gradient tolerance with contact: the residual along the sliding modes relaxes
# only as fast as their ~1e-8 stiffness allows, and barely couples to the crossing eigenvalue.
# 1e-7 (forces in units of B/l^2) is ~1e-7 of the twist moments in a twisted knot.
CONTACT_GTOL = 1e-7
# critical_twist: Newton steps on the crossing eigenvalue before the refinement gives up.
MAX_REFINE = 30
LINEAR_ALGEBRA = ("auto", "dense", "sparse")


class Task(str, enum.Enum):
    """What a continuation is for: its defaults differ (see ``ContinuationOptions``)."""

    CRITICAL_TWIST = "critical_twist"  # the first crossing, refined by Newton on the eigenvalue
    FOLLOW_TWIST = "follow_twist"  # a whole stable path, branch ends located to tol


@dataclass(frozen=True)
class ContinuationOptions:
    """Tolerances, budgets and behaviour of a twist continuation, every contact-aware default in
    one place. None means "the default for the scene and task": ``resolved(scene, task, span)``
    fills them in (and checks the values, ValueError naming the one that is wrong).

    Both entries:
    step: largest step in phi (rad). Default: critical_twist |phi_stop - phi_start| / 40,
      follow_twist 0.25 pi.
    tol: accuracy of the located critical twist or branch end (rad). Default: critical_twist
      1e-6 pi, follow_twist 2e-4 pi.
    negative_tol: an eigenvalue counts as negative below -negative_tol. Default 1e-10 (less for
      long rods: ``default_negative_tol``), or CONTACT_NEGATIVE_TOL = 1e-6 with self-contact
      (strands sliding along each other sit at |lambda| ~ 1e-7 and must not count).
    gtol: the equilibria's max |gradient| (scaled energy). Default 1e-9; critical_twist with
      contact CONTACT_GTOL = 1e-7 (the sliding modes relax only as fast as their stiffness allows).
    k: eigenpairs kept per state (default 8).

    critical_twist:
    max_refine: Newton steps on the crossing eigenvalue (default MAX_REFINE = 30).
    linear_algebra: "dense" (n x n Hessian, ``eigh``: O(n^3) per step), "sparse" (O(n) per step:
      without contact the block-tridiagonal Newton, inertia, eigenpairs and tangent of
      ``jaxrod.continuation.sparse_branch``; with contact SciPy's sparse LDL^T, ARPACK shift-invert and the
      host damped Newton of ``jaxrod.linalg.sparse_contact``) or "auto" (the default: sparse from
      n_dof >= 1000 on, else dense). follow_twist on rods without contact is dense only (it
      refuses "sparse").

    follow_twist:
    jump_tol: a corrector further than this from the predicted shape has left the branch.
      Default D/2 (or L/20 without a diameter).
    corrector_max_steps: damped-Newton iterations a corrector may take between two neighbourhood
      pauses (default CORRECTOR_MAX_STEPS = 60).
    branch: name of the branch started on (default 'symmetric'; '+' or '-' is appended).
    switch: at a branch end, switch to the stable buckled branch and go on (default True).
    max_switches: at most this many switches (default 3).
    perturbation: push along the critical mode when switching (default jump_tol).
    keep_symmetry: on a closed rod whose joint lies on a two-fold axis of the state followed (the
      trefoil as drawn), keep the states on that symmetry while the branch has it: a corrected
      state that drifted off it by less than ``jump_tol`` (material sliding along nearly null
      modes) is projected back and finished by the corrector (``jaxrod.model.symmetry``). Default True.
    check_branch: refuse a stable step across which one of the last state's lowest shape modes is
      predicted, by its eigenvalue's derivative along the branch, to cross zero; the end is then
      located as any other (``continuation.branch_check``: a minimiser past a branch point lands
      on the stable state beside the branch, and the instability was reported late); and halve,
      then accept with a warning, a step whose corrected state's lowest eigenvalues are not those
      predicted along the branch (``branch_check.departure``). Default True.

    ``updated(**values)`` is a copy with the values that are not None replaced.
    """

    step: float | None = None
    tol: float | None = None
    negative_tol: float | None = None
    gtol: float | None = None
    jump_tol: float | None = None
    k: int | None = None
    corrector_max_steps: int | None = None
    max_refine: int | None = None
    linear_algebra: str | None = None
    branch: str | None = None
    switch: bool | None = None
    max_switches: int | None = None
    perturbation: float | None = None
    keep_symmetry: bool | None = None
    check_branch: bool | None = None

    def updated(self, **values):
        """A copy with every value that is not None replaced."""
        return replace(self, **{key: v for key, v in values.items() if v is not None})

    def resolved(self, scene, task, span):
        """Every None filled in for ``scene`` (with or without contact) and ``task`` (a ``Task``);
        span: |phi_stop - phi_start|. Raises ValueError naming a value that is not allowed."""
        task = Task(task)
        contact = scene.has_term("contact")
        critical = task is Task.CRITICAL_TWIST
        defaults = {
            "step": span / 40.0 if critical else 0.25 * math.pi,
            "tol": 1e-6 * math.pi if critical else 2e-4 * math.pi,
            "negative_tol": CONTACT_NEGATIVE_TOL if contact else default_negative_tol(scene),
            "gtol": CONTACT_GTOL if (contact and critical) else 1e-9,
            "jump_tol": _jump_tolerance(scene),
            "k": 8,
            "corrector_max_steps": CORRECTOR_MAX_STEPS,
            "max_refine": MAX_REFINE,
            "linear_algebra": "auto",
            "branch": "symmetric",
            "switch": True,
            "max_switches": 3,
            "perturbation": None,  # jump_tol, once that is known
            "keep_symmetry": True,
            "check_branch": True,
        }
        values = {key: getattr(self, key) if getattr(self, key) is not None else d for key, d in defaults.items()}
        for key in ("step", "tol", "negative_tol", "gtol", "jump_tol"):
            values[key] = check_positive(key, abs(values[key]) if key == "step" else values[key])
        for key in ("k", "corrector_max_steps", "max_refine"):
            values[key] = check_int_at_least(key, values[key], 1)
        values["max_switches"] = check_int_at_least("max_switches", values["max_switches"], 0)
        values["perturbation"] = (values["jump_tol"] if values["perturbation"] is None
                                  else check_positive("perturbation", values["perturbation"]))
        if values["linear_algebra"] not in LINEAR_ALGEBRA:
            raise ValueError(f"linear_algebra must be 'auto', 'dense' or 'sparse', got {values['linear_algebra']!r}")
        if not critical and values["linear_algebra"] == "sparse" and not contact:
            raise ValueError("linear_algebra='sparse': follow_twist on a rod without contact is dense only (its "
                             "corrector is the dense damped-Newton minimiser of relax): use 'auto' or 'dense'")
        if values["switch"] not in (True, False):
            raise ValueError(f"switch must be True or False, got {values['switch']!r}")
        values["switch"] = bool(values["switch"])
        if values["keep_symmetry"] not in (True, False):
            raise ValueError(f"keep_symmetry must be True or False, got {values['keep_symmetry']!r}")
        values["keep_symmetry"] = bool(values["keep_symmetry"])
        if values["check_branch"] not in (True, False):
            raise ValueError(f"check_branch must be True or False, got {values['check_branch']!r}")
        values["check_branch"] = bool(values["check_branch"])
        if not isinstance(values["branch"], str) or not values["branch"]:
            raise ValueError(f"branch must be a non-empty name, got {values['branch']!r}")
        return ContinuationOptions(**values)


# Without contact, an eigenvalue counts as negative below -NEGATIVE_TOL_FRACTION times the bending
# scale (2 pi l / L)^4 of the rod (l the edge length, L the rod's length; in the scaled units the
# softest ring modes sit at 7.2 (2 pi / N)^4: 7.0e-10 at N = 2000, ~1e-12 at N = 10000), and never
# below DEFAULT_NEGATIVE_TOL. A fixed 1e-10 is far above those eigenvalues for N >~ 2000: the count
# changed a whole pi after the crossing (a ring of N = 2000 reported 6.27 pi for 5.20 pi) or all k
# eigenpairs computed were "near zero" (N >= 5800: "index 8 outside the 8 eigenpairs computed").
# Rods of N <= 628 nodes keep 1e-10. (``tolerances.scaled_negative_tol``.)
default_negative_tol = scaled_negative_tol


def _jump_tolerance(scene):
    D = scene.material.D
    return 0.5 * float(D) if D is not None else 0.05 * float(scene.length)


@dataclass(frozen=True)
class Observer:
    """What a continuation tells while it runs; every field is optional (None: not called).

    progress(str): progress lines (every entry, and ``twist_study``).
    on_step(phi, n_negative): ``critical_twist``, after every equilibrium of the scan and the
      refinement (e.g. a progress bar).
    on_point(PathPoint): ``follow_twist`` and ``twist_study``, after every accepted step (e.g. to
      write rows as they come); ``PathPoint.direction`` says which side ('plus' or 'minus';
      ``twist_study`` calls it from two threads when it runs both sides at once).
    on_instability(Instability): ``follow_twist``, as soon as a branch end is located (and, after
      a switch, before the new branch's first point), so that a study can keep it on file at once;
      ``twist_study`` calls it as on_instability(direction, index, critical.json entry, (q, phi) the
      last stable state before the end), once the end is on file.
    on_state(PathState): ``follow_twist``, after every step tried (and after the points and
      instabilities that step reported): what ``follow_twist(resume=...)`` goes on from.

    An entry refuses (ValueError) an observer with a field set that it never calls."""

    progress: object = None
    on_step: object = None
    on_point: object = None
    on_instability: object = None
    on_state: object = None

    def say(self, line):
        """Hand ``line`` to ``progress``, if set."""
        if self.progress is not None:
            self.progress(line)


def observed(observer, what, calls):
    """``observer`` (None: an Observer that calls nothing), checked: TypeError if it is not an
    ``Observer``, ValueError naming a field that is set but not among ``calls`` (the fields that
    ``what`` calls)."""
    if observer is None:
        return Observer()
    if not isinstance(observer, Observer):
        raise TypeError(f"observer must be a jaxrod.continuation.Observer, got {type(observer).__name__}")
    for f in fields(observer):
        if f.name not in calls and getattr(observer, f.name) is not None:
            raise ValueError(f"observer.{f.name}: {what} never calls it (it calls {', '.join(calls)})")
    return observer


def checked_options(options):
    """``options`` (None: ``ContinuationOptions()``); TypeError if it is not a
    ``ContinuationOptions`` (for example the pseudo-arclength engine's ``ArclengthOptions``)."""
    if options is None:
        return ContinuationOptions()
    if not isinstance(options, ContinuationOptions):
        raise TypeError(f"options must be a jaxrod.ContinuationOptions, got "
                        f"{type(options).__module__}.{type(options).__name__}")
    return options
