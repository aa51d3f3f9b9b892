"""The study's head start (``jaxrod.studies.twist.compile_ahead``): the per-step analysis run once on the drawn
shape in a thread beside the first relaxation must compile the very programs the continuation
then calls (same shapes, dtypes and weak types); a change that made them differ would silently
turn the head start into extra work. Checked by counting XLA compilations (persistent-cache loads
included) during the continuation's own analysis of the relaxed state."""
import jax.monitoring as monitoring

import jaxrod as jr
from jaxrod.linalg.stability import CONTACT_NEGATIVE_TOL, branch_analysis
from jaxrod.studies.twist import compile_ahead

COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"


def test_the_analysis_compiled_ahead_is_the_one_the_continuation_calls():
    scene = jr.trefoil(D=8.0, L=292.0, N=45)  # an N no other test uses: nothing of it compiled yet
    ahead = compile_ahead(scene)
    assert ahead is not None  # a dense knot: the head start runs
    relaxed = jr.relax_to_minimum(scene, 0.0)
    ahead.join()
    compiled = []

    def listen(event, seconds, **kwargs):
        if event == COMPILE_EVENT:
            compiled.append(seconds)

    monitoring.register_event_duration_secs_listener(listen)
    try:
        # as ``continuation.engine.ContinuationEngine.analyse`` calls it on each accepted state
        stab, *_ = branch_analysis(scene, relaxed.q, relaxed.phi, 0, k=8, tol=CONTACT_NEGATIVE_TOL, ref=None,
                                   pinv_tol=CONTACT_NEGATIVE_TOL, nbr=relaxed.neighbourhood)
    finally:
        monitoring.unregister_event_duration_listener(listen)
    assert stab.n_negative == 0
    assert compiled == []


def test_no_head_start_on_the_sparse_path():
    # from sparse_contact.SPARSE_MIN_DOF DOFs on the continuation calls other programs
    assert compile_ahead(jr.trefoil(D=8.0, L=292.0, N=251)) is None
