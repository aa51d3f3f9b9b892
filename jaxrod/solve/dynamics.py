"""Damped bead dynamics: the seed paper's own method, kept as a baseline to compare with.

The paper followed the dynamics of a bead model with viscous damping and white noise while the
twist is ramped, and read the critical twist where the writhe jumps. Here the jaxrod energy drives,
in the solvers' scaled variables u (unit mass per DOF):

    du/dt = v,    dv/dt = -grad E(u, phi(t)) - gamma v + sqrt(2 gamma T) xi(t),
    phi(t) = phi_start + rate t,

integrated by semi-implicit Euler (a Langevin thermostat at temperature T). Steps run in jitted
``lax.scan`` chunks with the neighbourhood frozen; between chunks the writhe is computed, the
neighbourhood rebuilt where stale, and a record kept (t, phi, energy, Wr, Tw). The transition is
where the writhe jumps by more than ``jump`` within a twist ``window``, reported as the twist of
the last record before the jump.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from .equilibrium import TopologyChangeError
from ..validation import check_finite, check_int_at_least, check_positive

__all__ = ["damped_dynamics", "DynamicsOptions", "DynamicsResult", "stable_time_step"]


@dataclass(frozen=True)
class DynamicsResult:
    """A damped-dynamics run. Records (one per chunk, the start included), each (R,): t (scaled
    time), phi (rad), energy, Wr, Tw, Lk. transition_phi: twist of the last record before the
    writhe transition (NaN if none); transition_index: its index (-1); stop: 'transition',
    'phi_stop' or 'topology' (a strand passed through another: take a smaller dt); q: final state
    (physical DOFs); steps; dt; seconds: wall time."""

    t: np.ndarray
    phi: np.ndarray
    energy: np.ndarray
    Wr: np.ndarray
    Tw: np.ndarray
    transition_phi: float
    transition_index: int
    stop: str
    q: np.ndarray = field(repr=False)
    steps: int = 0
    dt: float = 0.0
    seconds: float = 0.0

    @property
    def Lk(self):
        return self.Wr + self.Tw


@partial(jax.jit, static_argnames=("n_steps",))
def _run_chunk(scene, u, v, phi0, nbr, key, rate_dt, dt, gamma, sigma, n_steps):
    grad = jax.grad(scene.scaled_energy)

    def body(carry, i):
        u, v, key = carry
        key, sub = jax.random.split(key)
        g = grad(u, phi0 + rate_dt * i, nbr)
        v = v + dt * (-g - gamma * v) + sigma * jax.random.normal(sub, u.shape, dtype=u.dtype)
        return (u + dt * v, v, key), None

    (u, v, key), _ = jax.lax.scan(body, (u, v, key), jnp.arange(n_steps, dtype=u.dtype))
    return u, v, key


@jax.jit
def _observables(scene, u, phi, nbr):
    q = scene.from_scaled(u)
    return scene.energy(q, phi, nbr), scene.twist(q, phi, nbr)


@jax.jit
def _largest_curvature(scene, u, phi, nbr, probe):
    """Power iteration for the largest eigenvalue of the scaled Hessian (Hessian-vector products)."""
    grad = jax.grad(scene.scaled_energy)

    def hvp(w):
        return jax.jvp(lambda uu: grad(uu, phi, nbr), (u,), (w,))[1]

    def body(_, w):
        w = hvp(w)
        return w / jnp.linalg.norm(w)

    w = jax.lax.fori_loop(0, 60, body, probe / jnp.linalg.norm(probe))
    return jnp.dot(w, hvp(w))


def stable_time_step(scene, q, phi=0.0, safety=0.3):
    """A time step for ``damped_dynamics`` at state q: safety / sqrt(largest curvature of the
    scaled energy) (semi-implicit Euler is stable for dt < 2 / omega_max)."""
    u = jnp.asarray(scene.to_scaled(np.asarray(q, dtype=float)))
    nbr = scene.neighbourhood(np.asarray(q, dtype=float), phi)
    probe = jax.random.normal(jax.random.PRNGKey(1), u.shape, dtype=u.dtype)
    lam = float(_largest_curvature(scene, u, jnp.asarray(float(phi)), nbr, probe))
    return safety / math.sqrt(max(lam, 1e-300))


def _writhe_jump(phi, wr, jump, window):
    """Index of the earliest record at most ``window`` in twist before the newest (at least the
    one before it) whose writhe differs from the newest by more than ``jump``; -1 if none."""
    phi, wr = np.asarray(phi), np.asarray(wr)
    newest = len(wr) - 1
    inside = np.flatnonzero(np.abs(phi[newest] - phi[:newest]) <= window)
    if inside.size == 0:
        inside = np.array([newest - 1])
    far = inside[np.abs(wr[newest] - wr[inside]) > jump]
    return int(far[0]) if far.size else -1


@dataclass(frozen=True)
class DynamicsOptions:
    """The knobs of ``damped_dynamics`` (checked on construction; a ValueError names the field).

    gamma: damping rate (> 0, default 1); temperature: noise temperature T >= 0, scaled energy units
    (default 0); dt: time step (None: ``stable_time_step``); chunk: steps per jitted chunk and
    record (default 200); jump, window: a writhe change of more than ``jump`` (default 0.3) within
    ``window`` of twist (rad, default 0.1 pi) is the transition; departure: instead, the last record
    before the writhe leaves its start by more than ``departure`` (default None); seed: of the noise
    (default 0); stop_at_transition: stop at the first one (default True)."""

    gamma: float = 1.0
    temperature: float = 0.0
    dt: float | None = None
    chunk: int = 200
    jump: float = 0.3
    window: float = 0.1 * math.pi
    departure: float | None = None
    seed: int = 0
    stop_at_transition: bool = True

    def __post_init__(self):
        check_positive("gamma", self.gamma)
        if not (math.isfinite(self.temperature) and self.temperature >= 0.0):
            raise ValueError(f"temperature must be finite and >= 0, got {self.temperature!r}")
        if self.dt is not None:
            check_positive("dt", self.dt)
        check_int_at_least("chunk", self.chunk, 1)
        check_positive("jump", self.jump)
        check_positive("window", self.window)
        if self.departure is not None:
            check_positive("departure", self.departure)
        check_int_at_least("seed", self.seed, 0)


def _transition(records, departure, jump, window, say):
    """Index of the record after which the writhe made its transition (-1: none yet): a jump
    (``_writhe_jump``) or, given ``departure``, the first departure from the start by more."""
    if departure is None:
        transition = _writhe_jump(records["phi"], records["Wr"], jump, window)
    elif abs(records["Wr"][-1] - records["Wr"][0]) > departure:
        transition = len(records["Wr"]) - 2
    else:
        transition = -1
    if transition >= 0:
        say(f"transition: Wr {records['Wr'][transition]:.4f} -> {records['Wr'][-1]:.4f} after phi = "
            f"{records['phi'][transition] / math.pi:+.5f} pi")
    return transition


def damped_dynamics(scene, phi_start, phi_stop, rate, q0=None, options=None, *, progress=None):
    """Ramp the twist from phi_start to phi_stop at ``rate`` (rad per unit of scaled time) under
    damped, optionally noisy, bead dynamics, and detect the transition as the seed paper did. q0:
    initial state (default scene.q_init; start from a relaxed state); options: a
    ``DynamicsOptions``; progress: optional callable(str), a line every 50 records. Returns a
    ``DynamicsResult``."""
    t0 = time.perf_counter()
    if options is None:
        options = DynamicsOptions()
    elif not isinstance(options, DynamicsOptions):
        raise TypeError(f"options must be a DynamicsOptions, got {options!r}")
    gamma, temperature, chunk, jump, window = (float(options.gamma), float(options.temperature), int(options.chunk),
                                               float(options.jump), float(options.window))
    departure, seed, stop_at_transition = options.departure, options.seed, options.stop_at_transition
    phi_start = check_finite("phi_start", phi_start)
    phi_stop = check_finite("phi_stop", phi_stop)
    rate = check_positive("rate", abs(check_finite("rate", rate))) * (1.0 if phi_stop >= phi_start else -1.0)
    say = progress or (lambda s: None)
    q = np.asarray(scene.q_init if q0 is None else q0, dtype=float)
    if q.shape != (scene.n_dof,) or not np.all(np.isfinite(q)):
        raise ValueError(f"q0 must be a finite array of shape ({scene.n_dof},)")
    dt = stable_time_step(scene, q, phi_start) if options.dt is None else float(options.dt)
    sigma = math.sqrt(2.0 * gamma * temperature * dt)
    u = jnp.asarray(scene.to_scaled(q))
    v = jnp.zeros_like(u)
    key = jax.random.PRNGKey(int(seed))
    phi = phi_start
    nbr = scene.neighbourhood(q, phi)
    records = {"t": [], "phi": [], "energy": [], "Wr": [], "Tw": []}

    def record(t, phi, u, nbr):
        energy, tw = _observables(scene, u, jnp.asarray(phi), nbr)
        for name, value in (("t", t), ("phi", phi), ("energy", float(energy)), ("Wr", float(nbr.wr_ref)),
                            ("Tw", float(tw))):
            records[name].append(value)

    record(0.0, phi, u, nbr)
    steps, stop, transition = 0, "phi_stop", -1
    n_chunks = math.ceil(abs(phi_stop - phi_start) / (abs(rate) * dt * chunk))
    for k in range(n_chunks):
        u, v, key = _run_chunk(scene, u, v, jnp.asarray(phi), nbr, key, jnp.asarray(rate * dt), jnp.asarray(dt),
                               jnp.asarray(gamma), jnp.asarray(sigma), chunk)
        steps += chunk
        phi = phi_start + rate * dt * steps
        q = np.asarray(scene.from_scaled(np.asarray(u)))
        if not np.all(np.isfinite(q)):
            raise FloatingPointError(f"the dynamics blew up at phi = {phi / math.pi:+.6f} pi: "
                                     f"take a smaller dt (was {dt:.3g})")
        upd = nbr.update(scene, q, phi)
        new = upd.nbr
        if abs(float(new.wr_ref) - records["Wr"][-1]) >= 1.0 and scene.has_term("contact"):
            stop = "topology"  # a strand passed through another within one chunk
            nbr = new
            record(steps * dt, phi, u, nbr)
            break
        if upd.outdated:
            nbr = new
        else:
            nbr = type(nbr)(nbr.pairs, nbr.mask, nbr.x_built, nbr.skin, new.wr_ref)
        record(steps * dt, phi, u, nbr)
        if transition < 0:
            transition = _transition(records, departure, jump, window, say)
        if transition >= 0 and stop_at_transition:
            stop = "transition"
            break
        if k % 50 == 49:
            say(f"phi = {phi / math.pi:+.5f} pi, Wr = {records['Wr'][-1]:.4f}, E = {records['energy'][-1]:.6g}")
    if stop == "topology":
        raise TopologyChangeError(f"the writhe jumped by 1 or more within one chunk at phi = "
                                  f"{phi / math.pi:+.6f} pi: a strand "
                                  f"passed through another (take a smaller dt than {dt:.3g})")
    arrays = {name: np.asarray(values) for name, values in records.items()}
    return DynamicsResult(**arrays, transition_phi=float(arrays["phi"][transition]) if transition >= 0 else math.nan,
                          transition_index=transition, stop=stop, q=q, steps=steps, dt=dt,
                          seconds=time.perf_counter() - t0)
