"""jaxrod: equilibria and buckling of elastic rods under imposed twist.

Importing jaxrod switches JAX to float64 (``jax_enable_x64``): buckling thresholds are
located from eigenvalues that cross zero, which float32 cannot resolve.

It also defaults the BLAS thread count to 1 (``OPENBLAS_NUM_THREADS`` etc., only if unset and
only effective when jaxrod is imported before numpy/scipy): JAX's eigensolvers call LAPACK, and
on small matrices a multi-threaded OpenBLAS was measured ~100x slower on a 2-core machine.
"""
import os as _os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

from .model.material import Material  # noqa: E402
from .model.scenes import (  # noqa: E402
    ClampedRod,
    ClosedRod,
    FreeRod,
    clamped_critical_twist,
    clamped_rod,
    closed_curve,
    free_rod,
    figure_eight_energy,
    michell_critical_twist,
    michell_ring,
    ring,
    knot,
    torus_knot,
    trefoil,
)
from .solve.solvers import LBFGS, ConvergenceError, DampedNewton, Newton, Solution, StopReason, minimise  # noqa: E402
from .linalg.stability import Stability, critical_twist_derivative, eigenvalue_phi_derivative  # noqa: E402
from .solve.equilibrium import (  # noqa: E402
    Equilibrium, EquilibriumOptions, RelaxOptions, TopologyChangeError, relax, relax_to_minimum, solve_equilibrium,
)
from .continuation import (  # noqa: E402
    PathPoint, ContinuationOptions, CriticalPoint, Instability, NoCrossingError, Observer, PathStop, TwistPath,
    critical_twist, follow_twist,
)
from .solve.dynamics import DynamicsOptions, DynamicsResult, damped_dynamics  # noqa: E402
from .model import contact, topology  # noqa: E402
from .studies import endloads  # noqa: E402  (rods under end loads: jaxrod.studies.endloads)
from .continuation.kinds import EventKind  # noqa: E402
from .api import (  # noqa: E402
    CriticalEnd, CriticalTwists, SolveOptions, StabilityReport, critical_twist_sensitivity, critical_twists, equilibrium,
    stability,
)

# analysis (scipy.interpolate) and plotting (matplotlib) load on first use, e.g. ``jaxrod.io.plotting``:
# together they were 0.6 s of the 2.0 s ``import jaxrod`` (measured with -X importtime), paid by
# every script and CLI process that draws nothing.
_LAZY_SUBMODULES = {"analysis": ".measure.analysis", "plotting": ".io.plotting"}


def __getattr__(name):
    if name in _LAZY_SUBMODULES:
        import importlib

        return importlib.import_module(_LAZY_SUBMODULES[name], __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__version__ = "0.1.0"

# The public API: one name per task (``jaxrod.api`` describes them). The other attributes above
# (solvers, lower-level entries, result types of the engines) stay importable from here for the
# code that uses them, and are documented in their own modules.
__all__ = [
    # scenes: the shape positional, every quantity keyword-only (N nodes, D diameter, L length, material, nu)
    "Material",
    "ring",
    "michell_ring",
    "knot",
    "torus_knot",
    "clamped_rod",
    # an equilibrium at a twist, from a start
    "equilibrium",
    "SolveOptions",
    # stability: the one rule
    "stability",
    # continuation: on_point(PathPoint)
    "follow_twist",
    "ContinuationOptions",
    "Observer",
    # the critical twists on both sides, and their sensitivity to a parameter
    "critical_twists",
    "EventKind",
    "critical_twist_sensitivity",
]
