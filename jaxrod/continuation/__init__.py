"""Continuation of rod equilibria: one entry, two algorithms, one options class.

``continuation(problem, algorithm, options, *, observer)`` (``entry``): ``StableOnly()`` on a
``TwistProblem`` follows the stable branch in the imposed twist (-> ``TwistPath``);
``PseudoArclength()`` on a ``BifurcationProblem`` follows any branch, locating folds and branch
points (-> ``arclength.Branch``). The stable-only task entries: ``critical_twist`` (the first
twist where the negative count changes -> ``CriticalPoint``) and ``follow_twist`` (a whole stable
path with branch switching -> ``TwistPath``). Read in this order:

* ``entry``     continuation, TwistProblem
* ``algorithms``  StableOnly, PseudoArclength
* ``options``   ContinuationOptions (both algorithms), Task, Observer; the defaults (contact-aware tolerances)
* ``memory``    the dense path's memory estimate and its refusal before anything is compiled
* ``kinds``     EventKind: what both engines report (fold, branch point, unstable, jump ...)
* ``results``   CriticalPoint, PathPoint, Instability, TwistPath, PathStop
* ``engine``    the one predictor-corrector-accept step (ContinuationEngine, _Step, StepFailure)
* ``critical``  critical_twist
* ``state``     PathState: where a follow_twist run stands (exact resume, npz storage)
* ``ends``      where a followed branch ends: critical mode, end trials, phi*, the near-zero band
* ``switching`` the switch to the buckled branch
* ``snap``      where a branch that ended by a jump goes: Snap, snap_of
* ``follow``    follow_twist and its loop (_Follower)
* ``arclength`` the pseudo-arclength algorithm: corrector, events, location, switching, curves
"""
from ..linalg.stability import CONTACT_NEGATIVE_TOL, DEFAULT_NEGATIVE_TOL  # noqa: F401 (where callers have found them)
from .options import (CONTACT_GTOL, CORRECTOR_MAX_STEPS, LINEAR_ALGEBRA, MAX_REFINE,  # noqa: F401
                      NEGATIVE_TOL_FRACTION, ContinuationOptions, Observer, Task, default_negative_tol)
from .memory import (DENSE_BYTES_PER_DOF, DENSE_HESSIAN_COPIES, PROCESS_BASE_BYTES,  # noqa: F401
                     available_memory_bytes, check_dense_memory, dense_memory_bytes)
from .kinds import EventKind
from .results import (PathPoint, CriticalPoint, Instability, NoCrossingError,  # noqa: F401
                      PathStop, TwistPath)
from .engine import (K_MARGIN, STALL_FACTOR, ContinuationEngine, StepFailure, _Step,  # noqa: F401
                     grown_engine, uses_sparse)
from .critical import critical_twist
from .state import PathState, Phase
from .ends import branch_end_in_bracket, eigenvalue_past_zero, end_trial, negative_modes  # noqa: F401
from .ends import warn_if_band_hides_shape_modes
from .follow import follow_twist, follows_sparse
from .snap import Snap, snap_of
from .algorithms import PseudoArclength, StableOnly
from .entry import TwistProblem, continuation

__all__ = ["continuation", "TwistProblem", "StableOnly", "PseudoArclength", "check_dense_memory", "dense_memory_bytes", "available_memory_bytes", "default_negative_tol",
           "ContinuationOptions", "Observer", "Task", "PathStop", "StepFailure", "EventKind", "CriticalPoint",
           "critical_twist", "NoCrossingError", "PathPoint", "Instability", "TwistPath", "follow_twist", "follows_sparse",
           "Snap", "snap_of",
           "PathState", "Phase", "warn_if_band_hides_shape_modes"]
