"""A program is compiled once per structure, not once per object: two bifurcation problems of the
same rod relax through one compiled damped-Newton loop (counted from JAX's own compile log), and
scenes that differ only in their name share their programs."""
import logging

import jax
import jax.numpy as jnp
import numpy as np

import jaxrod as jr
from jaxrod.continuation.arclength.rods import pinned_problem


class _Compiles(logging.Handler):
    def __init__(self):
        super().__init__(logging.WARNING)
        self.names = []

    def emit(self, record):
        message = record.getMessage()
        if message.startswith("Compiling "):
            self.names.append(message.split()[1])


def test_two_problems_of_one_rod_relax_through_one_compiled_loop():
    scene = jr.michell_ring(N=12)
    q = np.asarray(scene.q_init)
    rods = [pinned_problem(scene, q, 0.0), pinned_problem(jr.michell_ring(N=12), q, 0.0)]
    handler, logger = _Compiles(), logging.getLogger("jax")
    logger.addHandler(handler)
    try:
        with jax.log_compiles(True):
            relaxed = [rod.problem.relax(rod.problem.u0, 0.5, rod.problem.args, gtol=1e-10)[0] for rod in rods]
    finally:
        logger.removeHandler(handler)
    assert all(sol.converged for sol in relaxed)
    assert np.allclose(relaxed[0].y, relaxed[1].y, rtol=0.0, atol=1e-12)
    assert handler.names.count("jit(_damped_newton_loop)") == 1, handler.names


def test_scenes_that_differ_only_in_their_name_share_one_compiled_program():
    """The trefoil drawn by ``trefoil`` and by ``knot('3_1')`` (and an atlas's knots at one N) have
    the same structure: one trace serves both, and each keeps its own name through jax's trees."""
    drawn = jr.trefoil(D=14.0, L=292.0, N=24)
    named = jr.knot("3_1", N=24, D=14.0, L=292.0)
    assert drawn.name != named.name
    traces = []

    @jax.jit
    def energy(s, u, nbr):
        traces.append(1)
        return s.energy(u, 1.0, nbr)

    q = jnp.asarray(drawn.q_init)
    nbr = drawn.neighbourhood(np.asarray(q))
    values = [float(energy(s, q, nbr)) for s in (drawn, named)]
    assert len(traces) == 1 and np.isfinite(values).all()
    copies = [jax.tree_util.tree_map(lambda leaf: leaf, s) for s in (drawn, named)]
    assert [c.name for c in copies] == [drawn.name, named.name]
