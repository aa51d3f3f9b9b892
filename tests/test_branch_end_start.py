"""A branch end's path (``jaxrod.studies.diagram.follow_branch_end``): it starts from a state that
the equilibrium solver called converged, and what it says beside a located end is true, with the
twist in multiples of pi."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

import jaxrod as jr
from jaxrod.continuation.arclength import Branch, Result
from jaxrod.continuation.arclength.continuation import why_not_located
from jaxrod.solve.equilibrium import RelaxOptions
from jaxrod.studies.diagram import START_TOL, DiagramOptions, end_message, follow_branch_end, twist_message

PI = math.pi


@pytest.fixture(scope="module")
def trefoil_relaxed():
    scene = jr.knot("3_1", D=8.0, L=292.0, N=61, nu=0.5)
    return scene, jr.equilibrium(scene, 0.0)


def test_a_converged_start_is_taken_with_the_default_tolerance(trefoil_relaxed):
    scene, eq = trefoil_relaxed
    end = follow_branch_end(scene, np.asarray(eq.q), eq.phi, 1.0, DiagramOptions(max_points=2, chunk=1))
    assert len(end.points) >= 2 and end.points[0].p == pytest.approx(eq.phi, abs=1e-12)


def test_a_converged_start_is_taken_below_newtons_reach(trefoil_relaxed):
    # newton_tol 1e-16 lies below the residual's roundoff floor (~2.5e-14 at N = 61): Newton cannot
    # reach it, but the start is a state the equilibrium solver called converged, so it is taken
    scene, eq = trefoil_relaxed
    end = follow_branch_end(scene, np.asarray(eq.q), eq.phi, 1.0,
                            DiagramOptions(newton_tol=1e-16, max_points=2, chunk=1))
    assert "start did not converge" not in end.message
    assert len(end.points) >= 1 and end.points[0].p == pytest.approx(eq.phi, abs=1e-12)
    assert START_TOL == RelaxOptions().gtol  # the equilibrium solver's own test


def _event(kind, phi, converged, residual=1e-14, eigenvalue=1e-14):
    return SimpleNamespace(kind=kind, p=phi, converged=converged, residual=residual,
                           critical_eigenvalue=eigenvalue, morse_before=1, morse_after=2)


def test_a_located_branch_point_is_said_to_be_located():
    located = _event("branch_point", 6.6 * PI, True)
    beyond = _event("fold", 6.7 * PI, False, residual=3e-4, eigenvalue=2e-5)
    path = Branch([], [located, beyond], Result.LOCATION_FAILED, why_not_located(beyond, 1e-10))
    message = end_message(located, path)
    assert message.startswith("branch_point located at +6.60000000 pi; past it: fold near phi = +6.7")
    assert "p = 21" not in message  # no twist in rad
    assert end_message(located, Branch([], [located], Result.STOPPED, "followed past the end")) == \
        "followed past the end"


def test_path_messages_give_the_twist_in_multiples_of_pi():
    boundary = Branch([], [], Result.BOUNDARY, f"p = {7.8 * PI:.12g} left [-inf, {7.75 * PI:.12g}]")
    assert twist_message(boundary) == "phi = +7.80000000 pi left [-inf, +7.750000] pi"
    failed = Branch([], [], Result.CORRECTOR_FAILED,
                    f"the corrector failed at every step size down to ds_min = 1e-06 from p = {-2 * PI:.12g} (point 4)")
    assert twist_message(failed).endswith("from phi = -2.00000000 pi (point 4)")
