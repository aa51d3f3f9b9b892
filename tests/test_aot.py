"""jaxrod.aot: programs exported by one process and loaded by the next, without tracing again."""
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod import aot

TRACED = {"count": 0}


def _body(scene, u, phi):
    TRACED["count"] += 1  # runs only while JAX traces
    return jax.grad(scene.scaled_energy)(u, phi), jnp.sum(u ** 2) * phi


def _shift(x, by):
    return x + by


@pytest.fixture
def folder(tmp_path):
    with aot.kept_in(str(tmp_path / "programs")) as where:
        yield where


def test_a_program_is_exported_once_and_loaded_without_tracing(folder):
    scene = jr.trefoil(D=8.0, L=292.0, N=40)
    u = scene.to_scaled(np.asarray(scene.q_init))
    plain = jax.jit(_body)(scene, u, jnp.asarray(0.3))
    first = aot.cached_jit(_body)
    g1, s1 = first(scene, u, jnp.asarray(0.3))
    files = os.listdir(folder)
    assert len(files) == 1 and "_body" in files[0]
    # a new wrapper (as in a new process): the program comes from the file, nothing is traced
    before = TRACED["count"]
    g2, s2 = aot.cached_jit(_body)(scene, u, jnp.asarray(0.3))
    assert TRACED["count"] == before
    np.testing.assert_array_equal(np.asarray(g2), np.asarray(g1))
    assert float(s2) == float(s1)
    np.testing.assert_allclose(np.asarray(g1), np.asarray(plain[0]), rtol=1e-12, atol=1e-12)
    # another shape is another program; a scene that differs only in its name (the left-handed
    # trefoil: other data, the same structure) is the same one, loaded without tracing
    aot.cached_jit(_body)(jr.trefoil(D=8.0, L=292.0, N=41), jr.trefoil(D=8.0, L=292.0, N=41).to_scaled(
        np.asarray(jr.trefoil(D=8.0, L=292.0, N=41).q_init)), jnp.asarray(0.3))
    assert len(os.listdir(folder)) == 2
    other = jr.trefoil(D=8.0, L=292.0, N=40, chirality="left")
    assert other.name != scene.name
    before = TRACED["count"]
    g3, _ = aot.cached_jit(_body)(other, other.to_scaled(np.asarray(other.q_init)), jnp.asarray(0.3))
    assert TRACED["count"] == before and len(os.listdir(folder)) == 2
    np.testing.assert_allclose(np.asarray(g3), np.asarray(jax.jit(_body)(other, other.to_scaled(
        np.asarray(other.q_init)), jnp.asarray(0.3))[0]), rtol=1e-12, atol=1e-12)


def test_static_arguments_key_the_program_or_keep_it_out(folder):
    shift = aot.cached_jit(_shift, static_argnames="by")
    assert float(shift(jnp.asarray(1.0), by=2.0)) == 3.0
    assert float(shift(jnp.asarray(1.0), by=5.0)) == 6.0
    assert len(os.listdir(folder)) == 2
    # a lambda has no stable name: it runs under plain jit, and nothing is written
    apply = aot.cached_jit(lambda x, f: f(x), static_argnames="f")
    assert float(apply(jnp.asarray(2.0), f=jnp.sin)) == pytest.approx(np.sin(2.0))
    assert len(os.listdir(folder)) == 2


def test_without_a_folder_it_is_plain_jit_and_the_setting_is_restored(tmp_path):
    assert aot.folder() is None
    before = TRACED["count"]
    scene = jr.trefoil(D=8.0, L=292.0, N=42)  # a shape no other test traced
    u = scene.to_scaled(np.asarray(scene.q_init))
    aot.cached_jit(_body)(scene, u, jnp.asarray(0.1))
    assert TRACED["count"] == before + 1
    with aot.kept_in(str(tmp_path / "p")):
        assert aot.folder() == str(tmp_path / "p")
    assert aot.folder() is None


def test_programs_of_another_code_version_are_removed(tmp_path):
    where = tmp_path / "programs"
    where.mkdir()
    (where / "0123456789abcdef-_body-00.jaxexport").write_bytes(b"old")
    mine = where / f"{aot.code_version()[:16]}-_body-11.jaxexport"
    mine.write_bytes(b"current")
    with aot.kept_in(str(where)):
        pass
    assert sorted(os.listdir(where)) == [mine.name]


def _scaled(x, by):
    return x * by


def test_weak_and_strong_scalars_and_repeated_calls_key_their_own_programs(folder):
    # A Python float is weakly typed, a NumPy float64 is not: two signatures, two programs; calling
    # again with either (the signature's key kept in memory) adds none and gives the same values.
    scaled = aot.cached_jit(_scaled)
    x = np.arange(3.0)
    first = [np.asarray(scaled(x, 2.0)), np.asarray(scaled(x, np.float64(2.0))), np.asarray(scaled(x[:2], 2.0))]
    assert len(os.listdir(folder)) == 3
    again = [np.asarray(scaled(x, 2.0)), np.asarray(scaled(x, np.float64(2.0))), np.asarray(scaled(x[:2], 2.0))]
    assert len(os.listdir(folder)) == 3
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(first[0], 2.0 * x)
