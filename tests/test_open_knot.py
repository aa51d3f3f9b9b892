"""The open overhand knot's builder, its linking number and its guard rails.

Fast (no relaxation: compiling the contact Hessian alone takes longer than this file may):
the pulled knot's loop size against T is measured by benchmarks/open_knot.py."""
import math

import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod.studies import open_knot as ok

N, L, D, LOOP = 60, 1.0, 1.0 / 55, 0.015


@pytest.fixture(scope="module")
def built():
    return ok.open_overhand_knot(N, L, D, LOOP)


def test_builder_geometry_and_linking(built):
    scene, q = built
    x = np.asarray(scene.nodes(jnp.asarray(q)))
    h = L / (N - 2)
    edges = np.linalg.norm(np.diff(x, axis=0), axis=1)
    assert np.all(edges <= 1.01 * h) and np.all(edges > 0.85 * h)  # resampled at the rest length
    assert 0.0 < float(scene.shortening) < L
    # the clamps are coaxial on z, the knot lies beside the axis, several D away
    assert np.allclose(x[[0, 1, -2, -1], :2], 0.0)
    assert 2 * D < ok.loop_height(scene, x) < 0.5
    # Lk = Lk0 + phi/2pi with Lk0 = +3 (the loose trefoil's crossings), for each end rotation
    for phi in (0.0, 2 * math.pi, -2 * math.pi):
        sc, qq = ok.open_overhand_knot(N, L, D, LOOP, phi=phi)
        assert sc.Lk0 == 3.0
        assert float(sc.linking_number(jnp.asarray(qq), phi)) == pytest.approx(3.0 + phi / (2 * math.pi), abs=1e-9)


def test_pull_step_keeps_topology(built):
    scene, q = built
    new, q2 = ok.moved_to_excess(scene, q, 0.8 * float(scene.shortening))
    x1 = np.asarray(scene.nodes(jnp.asarray(q)))
    x2 = np.asarray(new.nodes(jnp.asarray(q2)))
    assert float(new.shortening) == pytest.approx(0.8 * float(scene.shortening))
    # the far clamp moved, the near one did not; no edge torn near the far clamp
    assert np.allclose(x1[:2], x2[:2])
    assert np.max(np.linalg.norm(np.diff(x2, axis=0), axis=1)) < 1.2 * L / (N - 2)
    # the writhe moves continuously (no strand passage): Lk unchanged
    assert abs(float(new.writhe(jnp.asarray(q2))) - float(scene.writhe(jnp.asarray(q)))) < 0.3
    assert float(new.linking_number(jnp.asarray(q2), 0.0)) == pytest.approx(3.0, abs=1e-9)


def test_loop_span_is_the_diameter_of_the_off_axis_part(built):
    scene, _ = built
    # a circle of radius R in a plane containing the axis, touching the axis, plus nodes on the axis
    R = 10 * D
    t = np.linspace(0.0, 2 * math.pi, 400, endpoint=False)
    circle = np.stack([R + R * np.cos(t), np.zeros_like(t), 0.5 + R * np.sin(t)], axis=1)
    axis_nodes = np.stack([np.zeros(50), np.zeros(50), np.linspace(0.0, 1.0, 50)], axis=1)
    x = np.concatenate([axis_nodes, circle])
    assert ok.loop_height(scene, x) == pytest.approx(2 * R)
    assert ok.loop_span(scene, x) == pytest.approx(2 * R, rel=1e-4)
    assert ok.loop_span(scene, np.zeros((5, 3))) == 0.0


def test_fit_loose_limit_recovers_the_intercept():
    x = np.linspace(0.02, 0.2, 9)
    coef, err, res = ok.fit_loose_limit(x, 5.1 + 4.0 * x)
    assert coef == pytest.approx([5.1, 4.0]) and np.all(err < 1e-10) and res < 1e-12
    coef, err, res = ok.fit_loose_limit(x, 5.1 + 4.0 * x - 7.0 * x ** 2, degree=2)
    assert coef == pytest.approx([5.1, 4.0, -7.0])


def test_mean_tension_is_exact_for_the_loose_knot_law():
    # E = E_inf + c^2 B / e gives T = c^2 B / e^2; states in any order
    e = np.array([0.3, 0.1, 0.2, 0.15])
    e_mid, T = ok.mean_tension(e, 7.0 + 5.1 ** 2 / e)
    assert np.all(np.diff(e_mid) > 0)
    assert T == pytest.approx(5.1 ** 2 / e_mid ** 2, rel=1e-13)


def test_fit_prefactor_recovers_a_power_law():
    T = np.geomspace(10.0, 1000.0, 7)
    c, c_std, p, p_std = ok.fit_prefactor(T, 3.7 / np.sqrt(T))
    assert c == pytest.approx(3.7) and c_std < 1e-12 and p == pytest.approx(0.5) and p_std < 1e-12


@pytest.mark.parametrize("kwargs, name", [
    (dict(N=30), "N"), (dict(N=40), "N"), (dict(L=-1.0), "L"), (dict(D=0.0), "D"), (dict(loop=-0.1), "loop"),
    (dict(loop=0.2), "loop"), (dict(loop=1e-4), "loop"), (dict(phi=float("nan")), "phi"),
    (dict(options=dict(Lk0=2.5)), "Lk0"), (dict(options=dict(B=0.0)), "B"), (dict(options=dict(delta=2.0)), "delta"),
])
def test_bad_input_refused_naming_the_parameter(kwargs, name):
    args = dict(N=N, L=L, D=D, loop=LOOP)
    args.update(kwargs)
    with pytest.raises(ValueError, match=name):
        if "options" in args:
            args["options"] = ok.OpenKnotOptions(**args["options"])
        ok.open_overhand_knot(**args)


def test_pull_refuses_bad_excess(built):
    scene, q = built
    for bad in (0.0, -0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="excesses"):
            ok.pull(scene, q, [bad])
