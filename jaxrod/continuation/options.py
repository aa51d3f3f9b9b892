"""``ContinuationOptions`` (every knob of both algorithms; None: the default ``resolved`` or
``resolved_arclength`` fills in), ``Task`` (whose defaults) and ``Observer`` (the callbacks)."""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, fields, replace

from ..linalg.stability import CONTACT_NEGATIVE_TOL
from ..linalg.tolerances import NEGATIVE_TOL_FRACTION, scaled_negative_tol  # noqa: F401  (re-exported)
from ..validation import check_int_at_least, check_positive

# Damped-Newton iterations a corrector may take between two neighbourhood pauses: a step converges
# in 2-15 from the tangent predictor; one still crawling after 60 is off its branch and is refused.
CORRECTOR_MAX_STEPS = 60
# The corrector's gradient tolerance with contact (units of B/l^2): the sliding modes relax only as
# fast as their ~1e-8 stiffness allows, and barely couple to the crossing eigenvalue.
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
    """Tolerances, budgets and behaviour of a continuation, every contact-aware default in one place.

    Every field defaults to None, "the default for the scene and task", filled in when resolved; a
    field the chosen algorithm does not read is then refused, so a setting is never silently ignored.

    Parameters
    ----------
    step : float
        Both twist entries: largest step in phi (rad). Default: critical_twist
        |phi_stop - phi_start| / 40, follow_twist 0.25 pi.
    tol : float
        Both twist entries: accuracy of the located critical twist or branch end (rad).
        Default: critical_twist 1e-6 pi, follow_twist 2e-4 pi.
    bracket_tol : float
        follow_twist: width (rad) to which an end is bracketed where the bracket holds evidence of a
        fold or branch point, which a locator on the extended system then finds exactly
        (``jaxrod.studies.diagram.locate_end``): the lost state measured unstable, or the last
        stable state's critical eigenvalue modelled to reach zero inside the bracket. Every other
        end (a jump or failed corrector with no such model, a zero only predicted) is bracketed to
        tol. Default tol; it must not be less than tol.
    negative_tol : float
        Both twist entries: an eigenvalue counts as negative below -negative_tol (units of B/l).
        Default 1e-10 (less for long rods: ``default_negative_tol``), or CONTACT_NEGATIVE_TOL =
        1e-6 with self-contact (sliding strands sit at |lambda| ~ 1e-7 and must not count).
    gtol : float
        Both twist entries: the equilibria's max |gradient| (scaled energy). Default 1e-9;
        critical_twist with contact CONTACT_GTOL = 1e-7.
    k : int
        Both algorithms: eigenpairs kept per state (stable-only default 8, pseudo-arclength 4;
        pseudo-arclength keeps at least Morse index + 2).
    max_refine : int
        critical_twist: Newton steps on the crossing eigenvalue (default MAX_REFINE = 30).
    linear_algebra : {'auto', 'dense', 'sparse'}
        critical_twist: "dense" (n x n Hessian, O(n^3) per step), "sparse" (O(n) per step:
        ``jaxrod.continuation.sparse_branch`` without contact, ``jaxrod.linalg.sparse_contact``
        with it) or "auto" (the default: sparse from n_dof >= 1000 on). follow_twist on rods
        without contact is dense only (it refuses "sparse").
    jump_tol : float
        follow_twist: a corrector further than this from the predicted shape has left the branch
        (length unit of the scene, e.g. mm). Default D/2 (or L/20 without a diameter).
    corrector_max_steps : int
        follow_twist: damped-Newton iterations a corrector may take between two neighbourhood
        pauses (default CORRECTOR_MAX_STEPS = 60).
    branch : str
        follow_twist: name of the branch started on (default 'symmetric'; '+' or '-' is appended).
    switch : bool
        follow_twist: at a branch end, switch to the stable buckled branch and go on (default True).
    max_switches : int
        follow_twist: at most this many switches (default 3).
    perturbation : float
        follow_twist: push along the critical mode when switching (length; default jump_tol).
    keep_symmetry : bool
        follow_twist: on a closed rod whose joint lies on a two-fold axis of the state followed,
        keep the states on that symmetry while the branch has it: a corrected state that drifted
        off it by less than ``jump_tol`` is projected back and finished by the corrector
        (``jaxrod.model.symmetry``). Default True.
    check_branch : bool
        follow_twist: refuse a stable step across which one of the last state's lowest shape
        modes is predicted to cross zero (``continuation.branch_check``: a minimiser past a
        branch point lands on the stable state beside it); and halve, then accept with a
        warning, a step whose corrected spectrum is not the predicted one. Default True.
    ds, ds_min, ds_max : float
        Pseudo-arclength: first arclength step (default 0.05; its sign picks the initial direction
        of p), then adapted in [ds_min, ds_max] (defaults 1e-8, 0.2).
    p_min, p_max : float
        Pseudo-arclength: the run stops when p leaves [p_min, p_max] (that point is kept);
        default unbounded.
    max_steps : int
        Pseudo-arclength: at most this many steps (default 200); a step below ds_min that fails
        also stops the run.
    newton_tol : float
        Pseudo-arclength: absolute tolerance on the residual norm (default 1e-12).
    newton_max_iter : int
        Pseudo-arclength: Newton iterations per corrector (default 10).
    eig_rtol : float
        Pseudo-arclength: lambda < -eig_rtol * ||J|| counts as negative (default 1e-10).
    detect_events : bool
        Pseudo-arclength: detect and locate folds and branch points (default True).
    event_tol : float
        Pseudo-arclength: a located event must have residual and critical eigenvalue below it
        (default 1e-10).
    locate_max_iter : int
        Pseudo-arclength: Newton iterations to locate one event (default 20).
    soft_folds : {'slide', 'follow'}
        Pseudo-arclength: where the path turns back in p along a soft mode (an Event
        "soft_fold", only for problems with a ``soft_modes`` hook; on a loose knot, a
        saddle-node of the sliding landscape the discretisation adds). "slide" (default): relax
        at p_fold + slide_dp onwards, from the fold kicked by slide_kick downhill along its soft
        mode (steps capped at 10 slide_kick), and go on from the minimum reached (a ``Slide`` in
        ``Branch.slides``), as the physical rod would; "follow": follow the path back along the
        sliding saddles. Needs the problem's ``energy``.
    slide_dp, slide_kick : float
        Pseudo-arclength, soft_folds="slide": see above (defaults 1e-3 and 1e-2).
    resolve_crossings : float
        Pseudo-arclength (default 0: off): a step across which the Morse index changes by more
        than 1 is refused and retried at half the step, down to this step size, so that nearly
        coincident events fall into separate brackets; a crossing still multiple at that size is
        located as one multiple event. A refused step counts towards max_steps.
    report_at : tuple of float
        Pseudo-arclength: values of mu at which a two-parameter curve (``fold_curve``,
        ``branch_point_curve``) also gives a point exactly.

    Raises
    ------
    ValueError
        On construction, a pseudo-arclength value out of range; when resolved, a value that is
        not allowed or a field the algorithm does not read (the message names it).
    """

    step: float | None = None
    tol: float | None = None
    bracket_tol: float | None = None
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
    ds: float | None = None
    ds_min: float | None = None
    ds_max: float | None = None
    p_min: float | None = None
    p_max: float | None = None
    max_steps: int | None = None
    newton_tol: float | None = None
    newton_max_iter: int | None = None
    eig_rtol: float | None = None
    detect_events: bool | None = None
    event_tol: float | None = None
    locate_max_iter: int | None = None
    soft_folds: str | None = None
    slide_dp: float | None = None
    slide_kick: float | None = None
    resolve_crossings: float | None = None
    report_at: tuple | None = None

    def __post_init__(self):
        if any(getattr(self, key) is not None for key in ARCLENGTH_FIELDS):
            _check_arclength(self._arclength_values())

    def _arclength_values(self):
        values = {key: getattr(self, key) if getattr(self, key) is not None else d
                  for key, d in ARCLENGTH_DEFAULTS.items()}
        values["report_at"] = tuple(float(v) for v in values["report_at"])
        return values

    def updated(self, **values):
        """A copy with every value that is not None replaced."""
        return replace(self, **{key: v for key, v in values.items() if v is not None})

    def resolved(self, scene, task, span):
        """Every None filled in for ``scene`` and ``task`` (a ``Task``); span: |phi_stop - phi_start|.
        ValueError naming a value that is not allowed."""
        task = Task(task)
        _refuse_unread(self, ARCLENGTH_FIELDS, "the stable-only continuation")
        contact = scene.has_term("contact")
        critical = task is Task.CRITICAL_TWIST
        defaults = {
            "step": span / 40.0 if critical else 0.25 * math.pi,
            "tol": 1e-6 * math.pi if critical else 2e-4 * math.pi,
            "bracket_tol": None,  # tol, once that is known
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
        if values["bracket_tol"] is None:
            values["bracket_tol"] = values["tol"]
        elif check_positive("bracket_tol", values["bracket_tol"]) < values["tol"]:
            raise ValueError(f"bracket_tol must be at least tol = {values['tol']!r}, got {values['bracket_tol']!r}")
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
        return replace(self, **values)

    def resolved_arclength(self):
        """Every pseudo-arclength None filled in and checked (ValueError naming the one that is
        wrong, or a stable-only field that is set). Idempotent."""
        _refuse_unread(self, STABLE_ONLY_FIELDS, "pseudo-arclength continuation")
        values = self._arclength_values()
        _check_arclength(values)
        return replace(self, **values)


ARCLENGTH_DEFAULTS = {
    "ds": 0.05, "ds_min": 1e-8, "ds_max": 0.2, "p_min": -math.inf, "p_max": math.inf, "max_steps": 200,
    "newton_tol": 1e-12, "newton_max_iter": 10, "k": 4, "eig_rtol": 1e-10, "detect_events": True,
    "event_tol": 1e-10, "locate_max_iter": 20, "soft_folds": "slide", "slide_dp": 1e-3, "slide_kick": 1e-2,
    "resolve_crossings": 0.0, "report_at": (),
}
# The fields only one algorithm reads (k is read by both).
ARCLENGTH_FIELDS = tuple(key for key in ARCLENGTH_DEFAULTS if key != "k")
STABLE_ONLY_FIELDS = ("step", "tol", "bracket_tol", "negative_tol", "gtol", "jump_tol", "corrector_max_steps", "max_refine",
                      "linear_algebra", "branch", "switch", "max_switches", "perturbation", "keep_symmetry",
                      "check_branch")


def _refuse_unread(options, unread, algorithm):
    """ValueError naming the fields of ``options`` that are set but that ``algorithm`` never reads."""
    given = [key for key in unread if getattr(options, key) is not None]
    if given:
        raise ValueError(f"{', '.join(given)}: not read by {algorithm} (leave them None)")


def _check_arclength(v):
    """ValueError naming the pseudo-arclength value that is not allowed."""
    if v["soft_folds"] not in ("slide", "follow"):
        raise ValueError(f"soft_folds must be 'slide' or 'follow', got {v['soft_folds']!r}")
    if not (v["slide_dp"] > 0 and v["slide_kick"] > 0):
        raise ValueError("slide_dp and slide_kick must be > 0")
    if not (0 < v["ds_min"] <= abs(v["ds"]) <= v["ds_max"]):
        raise ValueError(f"need 0 < ds_min <= |ds| <= ds_max, got {v['ds_min']}, {v['ds']}, {v['ds_max']}")
    if not (v["resolve_crossings"] == 0.0 or v["ds_min"] <= v["resolve_crossings"]):
        raise ValueError("resolve_crossings must be 0 (off) or >= ds_min")
    if not v["p_min"] < v["p_max"]:
        raise ValueError("need p_min < p_max")
    if not all(math.isfinite(x) for x in v["report_at"]):
        raise ValueError(f"report_at: finite values, got {v['report_at']}")
    if v["max_steps"] < 1 or v["newton_max_iter"] < 1 or v["k"] < 1:
        raise ValueError("max_steps, newton_max_iter and k must be >= 1")


# Without contact, the negative threshold scales with the rod's bending scale (2 pi l / L)^4, so long
# rods' softest modes are not all "near zero" (``tolerances.scaled_negative_tol``).
default_negative_tol = scaled_negative_tol


def _jump_tolerance(scene):
    D = scene.material.D
    return 0.5 * float(D) if D is not None else 0.05 * float(scene.length)


@dataclass(frozen=True)
class Observer:
    """What a continuation tells while it runs; every field is optional (None: not called).

    An entry refuses an observer with a field set that it never calls.

    Parameters
    ----------
    progress : callable(str), optional
        Progress lines (every entry, and ``twist_study``).
    on_step : callable(phi, n_negative), optional
        ``critical_twist``, after every equilibrium of the scan and the refinement (phi in rad;
        e.g. a progress bar).
    on_point : callable(PathPoint), optional
        ``follow_twist`` and ``twist_study``, after every accepted step; ``PathPoint.direction``
        says which side ('plus' or 'minus'; ``twist_study`` may call it from two threads).
    on_instability : callable(Instability), optional
        ``follow_twist``, as soon as a branch end is located (before a new branch's first point);
        ``twist_study`` calls it as on_instability(direction, index, critical.json entry, (q, phi)
        the last stable state before the end), once the end is on file.
    on_state : callable(PathState), optional
        ``follow_twist``, after every step tried: what ``follow_twist(resume=...)`` goes on from.

    Raises
    ------
    TypeError
        Raised by the entry it is passed to, when given something other than an ``Observer``.
    ValueError
        Raised by the entry it is passed to, for a field set that it never calls (named).
    """

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
    ``Observer``, ValueError naming a set field not among ``calls`` (those ``what`` calls)."""
    if observer is None:
        return Observer()
    if not isinstance(observer, Observer):
        raise TypeError(f"observer must be a jaxrod.continuation.Observer, got {type(observer).__name__}")
    for f in fields(observer):
        if f.name not in calls and getattr(observer, f.name) is not None:
            raise ValueError(f"observer.{f.name}: {what} never calls it (it calls {', '.join(calls)})")
    return observer


def checked_options(options):
    """``options`` (None: ``ContinuationOptions()``); TypeError if not a ``ContinuationOptions``."""
    if options is None:
        return ContinuationOptions()
    if not isinstance(options, ContinuationOptions):
        raise TypeError(f"options must be a jaxrod.ContinuationOptions, got "
                        f"{type(options).__module__}.{type(options).__name__}")
    return options


def arclength_options(options):
    """``options`` (None: the defaults) resolved for pseudo-arclength (TypeError, ValueError as above)."""
    return checked_options(options).resolved_arclength()
