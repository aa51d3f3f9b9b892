"""Shared builders for the tests: small random non-planar states of each kind of rod."""
import numpy as np
import jax.numpy as jnp

from jaxrod import Material, closed_curve, clamped_rod, free_rod
from jaxrod.model import scenes

MAT = Material(B=1.3, C=0.9, EA=40.0)


def trefoil_points(n, scale=1.0):
    """The left-handed trefoil (z = -sin 3t) of ``jaxrod.model.scenes.trefoil_points``, scaled."""
    return scale * scenes.trefoil_points(n, chirality="left")


def wobbly_loop(n, seed=0, amp=0.15):
    """A non-planar closed curve (unknot) with random low-mode wobbles. Large amp can make near-cusps
    (seed 5: curvature radius 0.22 at amp 0.07, 0.0007 at amp 0.15)."""
    rng = np.random.default_rng(seed)
    s = 2 * np.pi * np.arange(n) / n
    x = np.stack([np.cos(s), np.sin(s), np.zeros(n)], axis=1)
    for k in (2, 3):
        c = rng.normal(size=(3, 2)) * amp
        x = x + np.cos(k * s)[:, None] * c[:, 0] + np.sin(k * s)[:, None] * c[:, 1]
    return x


def random_closed_state(n=9, seed=0, material=MAT):
    """A closed-rod scene and a random state q near its initial curve (twist angles random too)."""
    scene = closed_curve(wobbly_loop(n, seed), material=material)
    rng = np.random.default_rng(seed + 100)
    q = np.asarray(scene.q_init) + np.concatenate([0.02 * rng.normal(size=3 * n), 0.3 * rng.normal(size=n)])
    return scene, jnp.asarray(q)


def random_clamped_state(n=9, seed=0, material=MAT):
    scene = clamped_rod(N=n, length=1.0, material=material)
    rng = np.random.default_rng(seed)
    q = np.asarray(scene.q_init) + np.concatenate(
        [0.03 * rng.normal(size=3 * (n - 4)), 0.3 * rng.normal(size=n - 3)]
    )
    return scene, jnp.asarray(q)


def random_free_state(n=8, seed=0, material=MAT):
    scene = free_rod(N=n, length=1.0, material=material)
    rng = np.random.default_rng(seed)
    q = np.asarray(scene.q_init) + np.concatenate([0.03 * rng.normal(size=3 * n), 0.3 * rng.normal(size=n - 1)])
    return scene, jnp.asarray(q)


def analyze_checked(*args, **kwargs):
    """jaxrod.measure.analysis.analyze, with the warnings it issued checked against the ones it returns."""
    import warnings

    from jaxrod.measure.analysis import analyze

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = analyze(*args, **kwargs)
    assert [str(w.message) for w in caught] == list(res.warnings)
    return res
