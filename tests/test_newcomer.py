"""A newcomer's six tasks, each in at most ten lines, using only the names in ``jaxrod.__all__``, as
docs/getting-started.md writes them (its blocks run top to bottom here, once, and these tests check
their results): the trefoil (D = 8, L = 292, nu = 0.5) at N = 61 and Michell's ring. Also: the trefoil relaxed at
-4 pi from its zero-twist state is a minimum, and every function that reports stability gives it
the same Morse index and count of sliding modes."""
import math
import pathlib
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr

# The validation tier (-m validation): the getting-started page's trefoil, relaxed and followed to both ends.
pytestmark = pytest.mark.validation

PI = math.pi
PAGE = pathlib.Path(__file__).resolve().parent.parent / "docs" / "getting-started.md"
for _name in ("equilibrium", "stability", "critical_twists", "follow_twist", "knot", "michell_ring",
              "critical_twist_sensitivity", "Observer", "ContinuationOptions", "EventKind", "SolveOptions"):
    assert _name in jr.__all__, _name


@pytest.fixture(scope="module")
def page():
    """docs/getting-started.md's blocks run in order: the newcomer's six tasks as the page writes them."""
    namespace = {"__name__": "getting_started"}
    for block in re.findall(r"^```python\n(.*?)^```", PAGE.read_text(), flags=re.S | re.M):
        exec(compile(block, str(PAGE), "exec"), namespace)
    return namespace


@pytest.fixture(scope="module")
def trefoil(page):
    return page["trefoil"]


@pytest.fixture(scope="module")
def relaxed(page):
    return page["eq"]


@pytest.fixture(scope="module")
def ends(page):
    # the point study on both sides (twist study, each end located on the extended system)
    return page["ends"]


def test_the_page_has_six_tasks_in_public_names_only():
    text = PAGE.read_text()
    assert len(re.findall(r"^```python\n", text, flags=re.M)) == 6
    used = set(re.findall(r"\bjr\.(\w+)", "".join(re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M))))
    assert used and used <= set(jr.__all__), used - set(jr.__all__)


def test_1_the_trefoil_relaxed(relaxed):
    eq = relaxed
    assert sum(eq.energy_terms.values()) == pytest.approx(eq.energy, rel=1e-12)
    assert set(eq.energy_terms) >= {"stretch", "bend", "twist", "contact"}
    assert eq.Wr + eq.Tw == pytest.approx(eq.Lk, abs=1e-9) and eq.Lk == pytest.approx(3.0, abs=1e-6)
    assert eq.stability.morse_index == 0 and eq.stability.minimum


@pytest.mark.parametrize("sign", [1, -1])
def test_2_relaxed_at_plus_minus_4pi(trefoil, relaxed, sign):
    with pytest.warns(UserWarning, match="may land on another branch"):  # one solve 4 pi from its start
        eq = jr.equilibrium(trefoil, sign * 4 * PI, start=relaxed)
    assert eq.Lk == pytest.approx(3.0 + 2.0 * sign, abs=1e-6)
    assert eq.stability.minimum and eq.stability.morse_index == 0


def test_3_critical_twists_on_both_sides(ends):
    plus, minus = ends
    assert plus.kind in (jr.EventKind.FOLD, jr.EventKind.BRANCH_POINT)
    assert minus.kind in (jr.EventKind.FOLD, jr.EventKind.BRANCH_POINT)
    # README's N = 61 values (located ends, to 1e-3 pi): 6.601 pi and -11.475 pi
    assert plus.phi / PI == pytest.approx(6.601, abs=2e-3) and minus.phi / PI == pytest.approx(-11.475, abs=2e-3)
    assert min(plus.bracket) - 1e-3 <= plus.phi <= max(plus.bracket) + 1e-3
    assert plus.q.shape == minus.q.shape and plus.mode.ndim == 1


def test_3_the_sensitivity_of_a_knot_fold(trefoil, ends):
    end = next((e for e in ends if e.kind == jr.EventKind.FOLD), None)
    if end is None:
        pytest.skip("no fold among the located ends")
    slope = jr.critical_twist_sensitivity(trefoil, end, "nu")
    assert math.isfinite(slope) and slope != 0.0


def test_4_grad_of_the_energy(trefoil, relaxed):
    q, phi = jnp.asarray(relaxed.q), 2.0
    g = jax.grad(lambda q: trefoil.energy(q, phi))(q)
    dq = jnp.zeros_like(q).at[5].set(1e-4)
    fd = (trefoil.energy(q + dq, phi) - trefoil.energy(q - dq, phi)) / 2e-4
    assert float(g[5]) == pytest.approx(float(fd), rel=1e-5, abs=1e-9)
    energy = lambda nu: jr.knot("3_1", D=8.0, L=292.0, N=61, nu=nu).energy(q, phi)  # noqa: E731
    fd_nu = (3 * energy(0.5) - 4 * energy(0.5 - 1e-5) + energy(0.5 - 2e-5)) / 2e-5  # nu <= 0.5: one-sided
    assert float(jax.grad(energy)(0.5)) == pytest.approx(float(fd_nu), rel=1e-6)


def test_6_michell_ring_at_second_order(page):
    nu, N = page["nu"], page["N"]
    analytic = 2 * PI * math.sqrt(3.0) * (1.0 + nu)
    assert page["analytic"] == pytest.approx(analytic, rel=1e-15)
    for end, sign in ((page["plus"], 1), (page["minus"], -1)):
        rel = (sign * end.phi - analytic) / analytic
        assert 20.0 / N ** 2 < rel < 40.0 / N ** 2  # from above, c / N^2 with c ~ 31
    assert page["slope"] == pytest.approx(page["plus"].phi / (1.0 + nu), rel=1e-6)  # phi* ~ (1 + nu)


def test_5_a_continuation_that_records_the_writhe(page, relaxed):
    writhe, path = page["writhe"], page["path"]
    assert path.completed and len(writhe) == len(path.points) >= 3
    assert writhe[0] == pytest.approx(relaxed.Wr, abs=1e-6) and all(math.isfinite(w) for w in writhe)


def test_minus_4pi_is_a_minimum_under_every_stability_report(trefoil, relaxed):
    with pytest.warns(UserWarning):
        eq = jr.equilibrium(trefoil, -4 * PI, start=relaxed)
    reports = [eq.stability, jr.stability(trefoil, eq), jr.stability(trefoil, eq.q, eq.phi)]
    assert all(r.minimum for r in reports)
    assert len({(r.morse_index, r.n_sliding) for r in reports}) == 1
    assert reports[0].morse_index == 0
    with pytest.warns(UserWarning):
        any_state = jr.equilibrium(trefoil, -4 * PI, start=relaxed, options=jr.SolveOptions(minimum=False))
    report = any_state.stability
    assert report.minimum or report.saddle_kind in ("sliding", "shape")
    if not report.minimum:  # a saddle names the mode that makes it one, and the minimum lies lower
        assert report.eigenvalues[report.saddle_mode] < -report.band and eq.energy <= any_state.energy


def test_a_bare_state_needs_its_twist(trefoil):
    with pytest.raises(ValueError, match="phi"):
        jr.stability(trefoil, np.asarray(trefoil.q_init))
