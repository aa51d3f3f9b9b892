"""Pseudo-arclength continuation with event detection and exact location, for gradient systems.

    prob = BifurcationProblem(energy, u0, p0)          # F = grad_u E(u, p, args), J symmetric
    br = continuation(prob, PseudoArclength(), ContinuationOptions(ds=-0.1, p_max=2))
    br.events                                           # folds and branch points, located
    br, e = until_stable(prob, PseudoArclength(), opts, start=(u, p, t))   # an unstable branch until it
                                                        # restabilises (e: the fold/branch point, Morse -> 0)
    branches = switch_branches(prob, br.events[0], PseudoArclength(), opts)
    curve = fold_curve(prob, fold_event, set_mu, mu0, PseudoArclength(), opts_mu)
    fold_sensitivity(prob, fold_event, set_mu, mu0)     # dp*/dmu at the fold (implicit function theorem)
    fold_at(prob, fold_event, set_mu, mu0, mu1, opts)       # the fold at another mu (Newton on its system)
    branch_point_curve(prob, bp_event, set_mu, mu0, PseudoArclength(), opts_mu)   # a simple branch point in mu
    event_curve(prob, (u, p), set_mu, mu0, mus, EventCurveOptions(opts, delta))  # the first instability
                                                        # in mu, whatever its kind (a knot's phi*(D/L))

Modules: problem, results, corrector (tangent, bordered Newton, step control), continuation (the
entry), events, locate (extended systems), switching (reduced equations at branch points),
two_parameter (fold curves), event_curve (the first instability in mu through changes of kind).
"""
from .continuation import continuation, continuation_until, restabilisation, until_stable
from ...linalg.bordered import DenseBackend
from ..algorithms import PseudoArclength
from .problem import BifurcationProblem
from .results import Branch, ContinuationError, Event, Point, Result
from .switching import Emanating, emanating_directions, switch_branches
from .event_curve import EventCurve, EventCurveOptions, EventCurvePoint, branch_point_sensitivity, event_curve
from .two_parameter import FoldCurve, FoldPoint, branch_point_curve, fold_at, fold_curve, fold_sensitivity

__all__ = ["BifurcationProblem", "DenseBackend", "PseudoArclength", "continuation",
           "continuation_until", "until_stable", "restabilisation",
           "Branch", "Point", "Event", "Result", "ContinuationError", "Emanating", "emanating_directions",
           "switch_branches", "FoldCurve", "fold_curve", "FoldPoint", "fold_at", "fold_sensitivity",
           "branch_point_curve", "EventCurve", "EventCurveOptions", "EventCurvePoint", "event_curve", "branch_point_sensitivity"]
