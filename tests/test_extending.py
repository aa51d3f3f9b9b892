"""Extending jaxrod from outside: the example of docs/extending.md (two energy terms defined outside
the package, added to a clamped rod) runs as written, and the structured Hessian, every
linear-algebra backend and the continuation in phi work with the new terms."""
import pathlib
import re

import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.linalg.backend import Banded, Dense, Sparse
from jaxrod.model.hessian import dense_autodiff_hessian, scaled_hessian
from jaxrod.model.terms import Term

PAGE = pathlib.Path(__file__).resolve().parent.parent / "docs" / "extending.md"


@pytest.fixture(scope="module")
def example():
    """The namespace left by the page's python block (its own asserts checked on the way)."""
    (code,) = re.findall(r"^```python\n(.*?)^```", PAGE.read_text(), flags=re.S | re.M)
    namespace = {"__name__": "extending_example"}
    exec(compile(code, str(PAGE), "exec"), namespace)
    return namespace


def test_the_new_terms_join_the_scene(example):
    scene, rod = example["scene"], example["rod"]
    assert scene.term_names == ("stretch", "bend", "twist", "body force", "clamp spring")
    assert rod.term_names == ("stretch", "bend", "twist")  # the scene it was built from is unchanged
    assert scene.has_term("clamp spring") and not scene.has_term("contact")
    assert not scene.needs_neighbourhood


def test_the_energy_of_a_new_term(example):
    scene, eq, weight = example["scene"], example["eq"], example["weight"]
    x = np.asarray(scene.positions(jnp.asarray(eq.q)))
    expected = example["h"] * weight * np.sum(x[:, 2])  # -h sum force . x with force = (0, 0, -weight)
    assert eq.energy_terms["body force"] == pytest.approx(expected, rel=1e-13)
    total = float(scene.energy(jnp.asarray(eq.q), eq.phi))
    assert total == pytest.approx(sum(eq.energy_terms.values()), rel=1e-13)


def test_structured_hessian_is_the_autodiff_hessian(example):
    """At a generic (bent, unevenly twisted) state, so that every term's second derivative counts."""
    scene, eq = example["scene"], example["eq"]
    u = scene.to_scaled(np.asarray(eq.q)) + 0.05 * np.random.default_rng(1).standard_normal(scene.n_dof)
    u, phi = jnp.asarray(u), 2.0
    h = np.asarray(scaled_hessian(scene, u, phi, scene.neighbourhood(scene.from_scaled(u), phi)))
    reference = np.asarray(dense_autodiff_hessian(scene, u, phi))
    assert np.max(np.abs(h - reference)) <= 1e-12 * np.max(np.abs(reference))


def test_every_backend_sees_the_new_terms(example):
    scene, eq = example["scene"], example["eq"]
    u = jnp.asarray(scene.to_scaled(np.asarray(eq.q)))
    results = {}
    for backend in (Dense(), Banded(), Sparse()):
        assert backend.supports(scene)
        fac = backend.factorise(scene, u, eq.phi, eq.neighbourhood)
        results[backend.name] = (fac.inertia(), fac.lowest_eigenpairs(4).values)
    inertia, lowest = results["dense"]
    assert inertia.negative == 0 and inertia.zero == 0
    np.testing.assert_allclose(lowest, eq.stability.eigenvalues[:4], rtol=1e-10)
    for name, (other_inertia, other_lowest) in results.items():
        assert other_inertia == inertia, name
        np.testing.assert_allclose(other_lowest, lowest, rtol=1e-10, err_msg=name)


def test_critical_twist_is_the_plain_rods_moment(example):
    """phi* from the page: the plain rod, twisted to the same moment, has a vanishing eigenvalue
    (the weight shifts phi* by ~1e-5 relative: second order in the weight)."""
    rod, point = example["rod"], example["point"]
    C, L, compliance = example["C"], example["L"], example["compliance"]
    phi_plain = point.phi * (L / C) / compliance  # the plain rod's compliance is L / C
    assert phi_plain > point.phi  # the stiffer chain reaches the same moment at a smaller twist
    theta = phi_plain * np.arange(1, rod.n_dof - 3 * (rod.n_nodes - 4) + 1) / (rod.rest_lengths.shape[0] - 1)
    q = np.asarray(rod.q_init, dtype=float).copy()
    q[3 * (rod.n_nodes - 4):] = theta  # straight, the twist spread evenly: the plain rod's equilibrium
    at_rest = jr.stability(rod, np.asarray(rod.q_init), 0.0).eigenvalues[0]
    critical = jr.stability(rod, q, phi_plain).eigenvalues[0]
    assert abs(critical) < 1e-3 * at_rest


def test_terms_must_be_static_and_unique(example):
    rod, BodyForce = example["rod"], example["BodyForce"]
    with pytest.raises(TypeError, match="hashable"):
        rod.with_terms(BodyForce(np.array([0.0, 0.0, -1.0])))
    with pytest.raises(ValueError, match="unique"):
        rod.with_terms(BodyForce((0.0, 0.0, 1.0)), BodyForce((1.0, 0.0, 0.0)))
    with pytest.raises(TypeError, match="Term"):
        rod.with_terms(lambda scene, q, phi, nbr=None: 0.0)
    assert isinstance(BodyForce((0.0, 0.0, 1.0)), Term)
