"""Parameters jax can trace: ``jax.grad``, ``jax.jvp`` and ``jax.vmap`` over nu, D and the contact
stiffness through the public constructors (the scene built inside the traced function) and
through ``scene.with_params``, checked against central finite differences; concrete bad values
still raise the constructors' messages, and a tracer reaching a structural parameter is named."""
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr

# A trefoil thick enough (L/D = 20.9) that its drawn curve already presses strands together, so
# that the contact term, and its derivatives in D and the stiffness, are not zero.
D0, L0, N0, NU0, KC0 = 14.0, 292.0, 41, 0.4, 100.0
PHI = 1.0
RTOL = 1e-6


@pytest.fixture(scope="module")
def state():
    """The fixed state: the drawn curve (it does not depend on nu, D or the stiffness), perturbed."""
    q = np.asarray(jr.trefoil(D=D0, L=L0, N=N0).q_init)
    return jnp.asarray(q + 0.05 * np.random.default_rng(3).standard_normal(q.shape))


def trefoil_energy(q, nu=NU0, D=D0, kc=KC0, term=None):
    """Energy (or one term's) at (q, PHI) of the trefoil built from its public constructor."""
    scene = jr.trefoil(D=D, L=L0, N=N0, nu=nu, contact_stiffness=kc)
    if term is None:
        return scene.energy(q, PHI)
    return scene.energy_terms(q, PHI)[term]


def central_difference(f, x, h):
    return (f(x + h) - f(x - h)) / (2.0 * h)


# (parameter, its value, finite-difference step): steps balance truncation (h^2) and roundoff
PARAMETERS = [("nu", NU0, 1e-4), ("D", D0, 1e-4), ("kc", KC0, 1e-2)]


def test_the_fixed_state_touches_itself(state):
    assert float(trefoil_energy(state, term="contact")) > 1.0


@pytest.mark.parametrize("name,value,h", PARAMETERS)
def test_grad_through_the_constructor(state, name, value, h):
    f = lambda p: trefoil_energy(state, **{name: p})
    expected = central_difference(f, value, h)
    assert float(jax.grad(f)(value)) == pytest.approx(float(expected), rel=RTOL)


@pytest.mark.parametrize("name,value,h", [("D", D0, 1e-4), ("kc", KC0, 1e-2)])
def test_grad_of_the_contact_term(state, name, value, h):
    f = lambda p: trefoil_energy(state, term="contact", **{name: p})
    expected = central_difference(f, value, h)
    assert float(expected) != 0.0
    assert float(jax.grad(f)(value)) == pytest.approx(float(expected), rel=RTOL)


def test_jvp_along_nu_d_and_the_stiffness(state):
    """One directional derivative in (nu, D, kappa_c) at once."""
    f = lambda p: trefoil_energy(state, nu=p[0], D=p[1], kc=p[2])
    p0, t = jnp.array([NU0, D0, KC0]), jnp.array([1.0, -0.5, 2.0])
    value, slope = jax.jvp(f, (p0,), (t,))
    assert float(value) == float(trefoil_energy(state))  # the traced build gives the concrete energy
    h = 1e-5
    assert float(slope) == pytest.approx(float(central_difference(lambda s: f(p0 + s * t), 0.0, h)), rel=RTOL)


@pytest.mark.parametrize("name,values,h", [("nu", (0.0, 0.25, 0.45), 1e-4), ("D", (12.0, 13.0, 14.0), 1e-4),
                                           ("kc", (30.0, 100.0), 1e-2)])
def test_vmap_of_values_and_gradients(state, name, values, h):
    f = lambda p: trefoil_energy(state, **{name: p})
    batch = jnp.array(values)
    energies, slopes = jax.vmap(jax.value_and_grad(f))(batch)
    for v, e, s in zip(values, energies, slopes):
        assert float(e) == pytest.approx(float(f(v)), rel=1e-13)
        assert float(s) == pytest.approx(float(central_difference(f, v, h)), rel=RTOL)


def test_with_params_is_traceable(state):
    scene = jr.trefoil(D=D0, L=L0, N=N0, nu=0.5, contact_stiffness=KC0)
    f = lambda p: scene.with_params(nu=p[0], D=p[1], contact_stiffness=p[2]).energy(state, PHI)
    p0 = jnp.array([NU0, D0, 50.0])
    grad = jax.grad(f)(p0)
    for k, h in enumerate((1e-4, 1e-4, 1e-2)):
        e = jnp.zeros(3).at[k].set(1.0)
        expected = central_difference(lambda s: f(p0 + s * e), 0.0, h)
        assert float(grad[k]) == pytest.approx(float(expected), rel=RTOL)


def test_with_params_concrete_matches_the_constructor(state):
    """Concrete values give the scene the constructor builds, to the last bit."""
    built = jr.trefoil(D=D0, L=L0, N=N0, nu=0.1, contact_stiffness=30.0)
    updated = jr.trefoil(D=D0, L=L0, N=N0, nu=0.5).with_params(nu=0.1, contact_stiffness=30.0)
    assert float(updated.energy(state, PHI)) == float(built.energy(state, PHI))


def test_the_diameter_is_a_thicker_rod_of_the_same_material(state):
    """with_params(diameter=d) is the scene the constructor builds with D = d (same E, nu, L, N and
    contact stiffness): B and C scale as d^4, EA as d^2; its parameter value is D."""
    built = jr.trefoil(D=1.1 * D0, L=L0, N=N0, nu=0.5, contact_stiffness=KC0)
    scene = jr.trefoil(D=D0, L=L0, N=N0, nu=0.5, contact_stiffness=KC0)
    updated = scene.with_params(diameter=1.1 * D0)
    assert float(updated.energy(state, PHI)) == pytest.approx(float(built.energy(state, PHI)), rel=1e-13)
    assert float(updated.parameter("diameter")) == pytest.approx(1.1 * D0, rel=1e-15)
    assert float(updated.material.EA) == pytest.approx(1.21 * float(scene.material.EA), rel=1e-14)
    with pytest.raises(ValueError, match="diameter sets B, C, EA and D together"):
        scene.with_params(diameter=D0, C=1.0)
    both = scene.with_params(diameter=1.1 * D0, nu=0.3)  # nu sets C from the new B
    assert float(both.parameter("nu")) == pytest.approx(0.3, rel=1e-14)
    assert float(both.material.B) == pytest.approx(float(updated.material.B), rel=1e-15)


def test_michell_ring_gradients_in_nu_and_b():
    """The planar ring with its twist spread evenly (phi / N at each vertex) stores C phi^2 / (2 L),
    L = 2 pi, C = B / (1 + nu); its bending and stretching do not depend on nu."""
    N, phi = 24, 3.0
    q = jnp.asarray(jr.michell_ring(N=N).q_init).at[3 * N:].set(phi * jnp.arange(N) / N)

    def twist(nu, B=1.0):
        scene = jr.ring(N=N, material=jr.Material.from_ratio(B=B, nu=nu, D=0.01), radius=1.0)
        return scene.energy_terms(q, phi)["twist"]

    nu = 0.3
    exact = -phi**2 / (2.0 * 2.0 * math.pi * (1.0 + nu) ** 2)
    assert float(jax.grad(lambda n: jr.michell_ring(N=N, nu=n).energy(q, phi))(nu)) == pytest.approx(exact, rel=1e-9)
    assert float(jax.grad(twist)(nu)) == pytest.approx(exact, rel=1e-9)
    assert float(jax.grad(twist, argnums=1)(nu, 2.0)) == pytest.approx(float(twist(nu, 1.0)), rel=1e-12)
    assert float(jax.grad(jr.michell_critical_twist)(nu)) == pytest.approx(2.0 * math.pi * math.sqrt(3.0))
    B = jax.grad(lambda b: jr.Material(B=b, C=1.0, EA=1.0).B)(1.0)
    assert float(B) == 1.0


@pytest.mark.parametrize("build,message", [
    (lambda: jr.Material(B=-1.0, C=1.0, EA=1.0), "B must be positive"),
    (lambda: jr.Material(B=float("nan"), C=1.0, EA=1.0), "B must be finite"),
    (lambda: jr.michell_ring(N=12, nu=0.7), r"nu must lie in \(-1, 0.5\]"),
    (lambda: jr.trefoil(D=-8.0, L=292.0, N=41), "D must be positive"),
    (lambda: jr.trefoil(D=8.0, L=292.0, N=41, contact_stiffness=0.0), "contact_stiffness must be positive"),
    (lambda: jr.trefoil(D=8.0, L=100.0, N=41), "below the ideal trefoil's ropelength"),
    (lambda: jr.trefoil(D=8.0, L=292.0, N=30), "self-contact needs edges no longer than the diameter"),
    (lambda: jr.michell_ring(N=12).with_params(nu=-1.0), r"nu must lie in \(-1, 0.5\]"),
    (lambda: jr.michell_ring(N=12).with_params(B=0.0), "B must be positive"),
    (lambda: jr.michell_ring(N=12).with_params(nu=0.1, C=1.0), "give C or nu"),
    (lambda: jr.michell_ring(N=12).with_params(E=1.0), "with_params sets"),
    (lambda: jr.clamped_rod(N=8, length=1.0, material=jr.Material(1.0, 1.0, 1.0)).with_params(contact_stiffness=1.0),
     "has no contact stiffness"),
])
def test_concrete_bad_values_still_raise(build, message):
    with pytest.raises(ValueError, match=message):
        build()


def test_a_tracer_reaching_a_structural_parameter_is_named():
    with pytest.raises(ValueError, match="N must be a concrete value"):
        jax.grad(lambda n: jr.michell_ring(N=n).energy(jnp.zeros(1), 0.0))(12.0)
    with pytest.raises(ValueError, match="Lk0 must be a concrete value"):
        jax.grad(lambda k: jr.ring(N=8, material=jr.Material(1.0, 1.0, 1.0), Lk0=k).energy(jnp.zeros(32), 0.0))(1.0)


def test_a_traced_array_is_not_a_parameter():
    with pytest.raises(ValueError, match="B must be a real number, got a traced array of shape"):
        jax.jacfwd(lambda b: jr.Material(B=b, C=1.0, EA=1.0).B)(jnp.ones(2))


def test_the_neighbourhood_asks_for_a_concrete_diameter(state):
    scene = jr.trefoil(D=D0, L=L0, N=N0)
    with pytest.raises(ValueError, match="D must be a concrete value to build a neighbourhood"):
        jax.grad(lambda d: scene.with_params(D=d).neighbourhood(state).wr_ref)(D0)


def test_a_scene_of_python_floats_and_one_of_numpy_values_share_one_compiled_program():
    """jit keys weakly typed values (Python floats) apart from float64 ones: the same scene built
    from floats, set by ``with_params`` from numpy values, or with a neighbourhood read from a file
    must still reach a program by the same key, or every program is compiled twice."""
    scene = jr.trefoil(D=D0, L=L0, N=24, nu=NU0, contact_stiffness=KC0)
    q = np.asarray(scene.q_init)
    nbr = scene.neighbourhood(q)
    other = scene.with_params(nu=np.float64(NU0), contact_stiffness=np.float64(KC0))
    loaded = type(nbr)(*(jnp.asarray(np.asarray(leaf)) for leaf in (nbr.pairs, nbr.mask, nbr.x_built, nbr.skin,
                                                                     nbr.wr_ref)))
    for tree in (scene, other, nbr, loaded):
        weak = [leaf for leaf in jax.tree_util.tree_leaves(tree) if jnp.asarray(leaf).weak_type]
        assert not weak, (type(tree).__name__, weak)
    traces = []

    @jax.jit
    def energy(s, u, neighbourhood):
        traces.append(1)
        return s.energy(u, PHI, neighbourhood)

    values = [float(energy(s, jnp.asarray(q), n)) for s, n in ((scene, nbr), (other, loaded), (scene, loaded))]
    assert len(traces) == 1
    assert values[0] == pytest.approx(values[1], rel=1e-12) and values[2] == values[0]
