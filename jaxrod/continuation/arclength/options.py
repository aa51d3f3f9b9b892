"""Continuation options (one object) and the pseudo-arclength algorithm's own settings."""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class ArclengthOptions:
    """Step, bounds and tolerances of a continuation run.

    ds: first step (its sign picks the initial direction of p); |ds| is then adapted in
    [ds_min, ds_max] from the corrector's convergence. The run stops when p leaves
    [p_min, p_max] (that point is kept), after max_steps steps, or when a step below ds_min fails.
    newton_tol: absolute tolerance on the residual norm; n_eig: eigenpairs kept per point (at least Morse index + 2);
    eig_rtol: lambda < -eig_rtol * ||J|| counts as negative; event_tol: a located event must have
    residual and critical eigenvalue below it; locate_max_iter: Newton iterations to locate one.

    soft_folds: what to do where the path turns back in p along a soft mode (an Event
    "soft_fold", only for problems with a ``soft_modes`` hook; on a loose knot, a saddle-node of the
    tiny sliding landscape that the discretisation adds to the slide, which is a symmetry of the
    continuum rod). "slide" (default): relax at p_fold + slide_dp in the direction the path was
    going, from the fold kicked by slide_kick downhill along its soft mode (steps capped at 10
    slide_kick), and go on from the minimum reached (a ``Slide`` in ``Branch.slides``), as the
    physical rod would, its strands slipping by a fraction of an edge; "follow": follow the path back along the sliding saddles.
    Needs the problem's ``energy``.

    resolve_crossings: a step control that watches the spectrum (0: off). A step across which the
    Morse index changes by more than 1 (several eigenvalues crossing zero between two points, e.g.
    a fold next to a symmetry pair) is refused and retried at half the step, down to this step
    size, so that nearly coincident events fall into separate brackets; a crossing that is still
    multiple at that size is a multiple event (a symmetric double branch point), located as one.
    A refused step counts towards max_steps.

    report_at: values of the continued parameter at which a two-parameter curve (``fold_curve``,
    ``branch_point_curve``: values of mu) also gives a point exactly, corrected on the hyperplane
    mu = value from the chord of the step that crosses it.
    """

    ds: float = 0.05
    ds_min: float = 1e-8
    ds_max: float = 0.2
    p_min: float = -math.inf
    p_max: float = math.inf
    max_steps: int = 200
    newton_tol: float = 1e-12
    newton_max_iter: int = 10
    n_eig: int = 4
    eig_rtol: float = 1e-10
    detect_events: bool = True
    event_tol: float = 1e-10
    locate_max_iter: int = 20
    soft_folds: str = "slide"
    slide_dp: float = 1e-3
    slide_kick: float = 1e-2
    resolve_crossings: float = 0.0
    report_at: tuple = ()

    def __post_init__(self):
        if self.soft_folds not in ("slide", "follow"):
            raise ValueError(f"soft_folds must be 'slide' or 'follow', got {self.soft_folds!r}")
        if not (self.slide_dp > 0 and self.slide_kick > 0):
            raise ValueError("slide_dp and slide_kick must be > 0")
        if not (0 < self.ds_min <= abs(self.ds) <= self.ds_max):
            raise ValueError(f"need 0 < ds_min <= |ds| <= ds_max, got {self.ds_min}, {self.ds}, {self.ds_max}")
        if not (self.resolve_crossings == 0.0 or self.ds_min <= self.resolve_crossings):
            raise ValueError("resolve_crossings must be 0 (off) or >= ds_min")
        if not self.p_min < self.p_max:
            raise ValueError("need p_min < p_max")
        object.__setattr__(self, "report_at", tuple(float(v) for v in self.report_at))
        if not all(math.isfinite(v) for v in self.report_at):
            raise ValueError(f"report_at: finite values, got {self.report_at}")
        if self.max_steps < 1 or self.newton_max_iter < 1 or self.n_eig < 1:
            raise ValueError("max_steps, newton_max_iter and n_eig must be >= 1")


@dataclass(frozen=True)
class PseudoArclength:
    """Keller's pseudo-arclength: tangent predictor, Newton on the bordered (n+1) corrector.

    min_cos: a step whose tangent turns by more than acos(min_cos) is refused and retried smaller
    (it may have jumped to another branch), and so is one whose corrector moved the point by
    more than ``max_correction`` * ds from the predictor. Measured on the trefoil at N = 121, whose
    opening fold sits next to a nearly degenerate pair of modes: without that test, paths with
    ds_max = 0.25 and 1 landed on a nearby branch there (tangents still within min_cos) and found
    another fold; with it, ds_max = 0.25, 0.4 and 1 from two starts give the same fold to 1e-14 pi,
    the accepted steps next to it corrected by at most 0.18 ds. The step grows by ``grow`` after a corrector that
    needed at most ``fast_iterations`` iterations, shrinks by ``shrink`` on failure.
    """

    min_cos: float = 0.9
    max_correction: float = 0.2
    grow: float = 1.5
    shrink: float = 0.5
    fast_iterations: int = 3
