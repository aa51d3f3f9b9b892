"""Programs kept across processes: the heaviest jitted functions, exported once (``jax.export``)
and loaded by later processes without tracing or lowering them again.

JAX's persistent compilation cache (which the CLI turns on) keeps the compiled executables, but a
new process must still trace every function to a jaxpr and lower it to StableHLO before it can
even look one up: on the README's command 1 that was ~5 s of tracing and ~3 s of lowering in
every run, of which a handful of functions took most (the structured Hessian's forward-mode
derivative alone traces for 1.3 s). ``cached_jit(fn)`` is ``jax.jit(fn)`` that, once ``enable``
has named a folder, stores each (function, argument structure, shapes) it compiles there as a
serialized ``jax.export.Exported`` (a StableHLO module in a flatbuffer; no pickle) and, in a
later process, calls the deserialized module instead: its lowering is the module itself, and its
compilation comes from the persistent cache as before.

The key of a stored program is a SHA-256 of the function's module and name, the arguments' tree
structure (a scene's static fields included), each leaf's shape, dtype and weak type, the static
arguments, the source of every jaxrod module, and the versions of JAX and jaxlib: a program is
reused only by the same code on the same kinds of arguments. Anything that cannot be keyed safely
(a static argument that is not a module-level function or a plain value, a tree structure whose
printed form is abbreviated) or exported (a custom call without a stable ABI) falls back to
``jax.jit``, as does every call while no folder is enabled (the library's default: nothing is
written unless the CLI or the user asks for it). What the key cannot see: a module-level constant
changed at run time (a test's monkeypatch) is baked into a program exported before it; keep
programs only around code that is not patched (the CLI enables it for its own command only).

A kept program is the same computation lowered once more, inside a wrapper: XLA may fuse it
differently, so its results can differ from ``jax.jit``'s in the last bits (command 1: the
located events agree to 1e-14 relative).
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import inspect
import os
import threading

import jax
import numpy as np

__all__ = ["cached_jit", "enable", "folder", "kept_in"]

_STATE = {"folder": None}  # the one setting: where programs are kept (None: plain jax.jit)
_LOCK = threading.Lock()


def enable(path):
    """Keep exported programs in the folder ``path`` (created if needed); None turns it off.
    Returns whether programs are now kept (False without the ``flatbuffers`` package, which
    ``jax.export`` serializes with)."""
    if path is not None:
        try:
            import flatbuffers  # noqa: F401
        except ImportError:
            path = None
        else:
            os.makedirs(path, exist_ok=True)
            _prune(path)
    _STATE["folder"] = path
    return path is not None


def _prune(path):
    """Remove the programs of other code versions (an upgraded or edited jaxrod never reads
    them again; each file's name starts with the version it was exported by)."""
    mine = code_version()[:16] + "-"
    for name in os.listdir(path):
        if name.endswith(".jaxexport") and not name.startswith(mine):
            try:
                os.remove(os.path.join(path, name))
            except OSError:
                pass


@contextlib.contextmanager
def kept_in(path):
    """``enable(path)`` for the duration of a with-block, the previous setting restored after it
    (the CLI keeps programs for its own command only, not for a caller's later API calls)."""
    previous = _STATE["folder"]
    try:
        enable(path)
    except OSError:  # the folder cannot be made: run without
        enable(None)
    try:
        yield _STATE["folder"]
    finally:
        _STATE["folder"] = previous


def folder():
    """The folder programs are kept in, or None."""
    return _STATE["folder"]


@functools.lru_cache(maxsize=1)
def code_version():
    """SHA-256 of every jaxrod module's source and of JAX's and jaxlib's versions."""
    import jaxlib

    h = hashlib.sha256(f"jax {jax.__version__} jaxlib {jaxlib.__version__} "
                       f"x64 {jax.config.jax_enable_x64}".encode())
    root = os.path.dirname(os.path.abspath(__file__))
    for base, dirs, files in sorted(os.walk(root)):
        dirs.sort()
        for name in sorted(files):
            if name.endswith(".py"):
                with open(os.path.join(base, name), "rb") as f:
                    h.update(name.encode() + b"\0" + f.read())
    return h.hexdigest()


def _static_key(value):
    """A stable text for a static argument, or None where there is none (a lambda, a bound
    method, an object without a faithful repr): that call is then not kept."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return repr(value)
    if isinstance(value, tuple) and all(isinstance(v, (bool, int, float, str)) for v in value):
        return repr(value)
    if inspect.isfunction(value) and "<" not in value.__qualname__:
        module = inspect.getmodule(value)
        if module is not None and getattr(module, value.__qualname__, None) is value:
            return f"{module.__name__}.{value.__qualname__}"
        return None
    if dataclasses.is_dataclass(value) and not isinstance(value, type) and value.__dataclass_params__.frozen:
        # a frozen dataclass (a linear-algebra backend) by its class and fields
        fields = [_static_key(getattr(value, f.name)) for f in dataclasses.fields(value)]
        if None not in fields:
            return f"{type(value).__module__}.{type(value).__qualname__}({', '.join(fields)})"
    return None


def _leaf_key(leaf):
    aval = jax.typeof(leaf)
    return f"{aval.shape}{aval.dtype}{'w' if getattr(aval, 'weak_type', False) else ''}"


def cached_jit(fn=None, *, static_argnames=()):
    """``jax.jit(fn, static_argnames=...)``, whose programs are kept across processes while
    ``enable`` has named a folder (see the module docstring). fn must return an array or a flat
    pytree of plain containers (a NamedTuple or dataclass output is not kept: jax.jit then runs
    it). Usable as a decorator."""
    if fn is None:
        return functools.partial(cached_jit, static_argnames=static_argnames)
    static = tuple([static_argnames] if isinstance(static_argnames, str) else static_argnames)
    jitted = jax.jit(fn, static_argnames=static or None)
    signature = inspect.signature(fn)
    programs = {}  # key -> jitted exported.call, or None: not kept
    memo = {}  # (treedef, leaf types, statics) -> key: the text and hash once per signature

    @functools.wraps(fn)
    def call(*args, **kwargs):
        where = _STATE["folder"]
        if where is None:
            return jitted(*args, **kwargs)
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        statics = {k: bound.arguments[k] for k in static}
        dynamic = [(k, v) for k, v in bound.arguments.items() if k not in static]
        leaves, treedef = jax.tree_util.tree_flatten([v for _, v in dynamic])
        if any(isinstance(x, jax.core.Tracer) for x in leaves):  # called inside another trace
            return jitted(*args, **kwargs)
        key = _memo_key(memo, fn, treedef, leaves, statics)
        if key is None:
            return jitted(*args, **kwargs)
        program = programs.get(key, False)
        if program is False:
            with _LOCK:
                program = programs.get(key, False)
                if program is False:
                    name = f"{code_version()[:16]}-{fn.__qualname__}-{key[:24]}.jaxexport"
                    program = programs[key] = _load_or_export(fn, statics, [k for k, _ in dynamic], treedef,
                                                              leaves, os.path.join(where, name))
        if program is None:
            return jitted(*args, **kwargs)
        return program(*leaves)

    call.jitted = jitted
    return call


def _leaf_type(leaf):
    """A hashable stand-in for a leaf's abstract value (shape, dtype, weak type) that is cheap to
    take; None where it is not plain (``_key`` then takes jax.typeof)."""
    if type(leaf) in (float, int, bool):  # Python scalars: weakly typed
        return type(leaf).__name__
    if isinstance(leaf, (np.ndarray, np.generic)):
        return np.shape(leaf), leaf.dtype.str, False
    if isinstance(leaf, jax.Array):
        return leaf.shape, leaf.dtype.str, bool(getattr(leaf, "weak_type", False))
    return None


def _memo_key(memo, fn, treedef, leaves, statics):
    """``_key``, kept in ``memo`` per signature (the treedef, the leaves' types and the statics),
    so that a program called thousands of times hashes its signature once."""
    types = tuple(_leaf_type(x) for x in leaves)
    try:
        signature = (treedef, types, tuple(sorted(statics.items())))
        hash(signature)
    except TypeError:  # an unhashable static: no memo
        signature = None
    if signature is None or None in types:
        return _key(fn, treedef, leaves, statics)
    if signature not in memo:
        memo[signature] = _key(fn, treedef, leaves, statics)
    return memo[signature]


def _key(fn, treedef, leaves, statics):
    tree = str(treedef)
    if "..." in tree:  # an abbreviated static field (a long array's repr): not a faithful key
        return None
    parts = [f"{fn.__module__}.{fn.__qualname__}", tree, ",".join(_leaf_key(x) for x in leaves), code_version()]
    for name in sorted(statics):
        text = _static_key(statics[name])
        if text is None:
            return None
        parts.append(f"{name}={text}")
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


def _load_or_export(fn, statics, names, treedef, leaves, path):
    """jax.jit(exported.call) from ``path``, or exported now and written there; None where fn
    cannot be exported or its output serialized (its calls then go to jax.jit)."""
    from jax import export

    try:
        with open(path, "rb") as f:
            return _named_call(export.deserialize(bytearray(f.read())), fn)
    except OSError:
        pass
    except Exception:  # noqa: BLE001 -- a damaged or foreign file: exported again below
        pass

    def flat(*xs):
        values = jax.tree_util.tree_unflatten(treedef, list(xs))
        return fn(**dict(zip(names, values)), **statics)

    flat.__name__ = flat.__qualname__ = fn.__name__  # JAX's compile logs and events name the program

    try:
        exported = export.export(jax.jit(flat))(*leaves)
        data = bytes(exported.serialize())  # fails for outputs that are not plain containers
    except Exception:  # noqa: BLE001 -- e.g. a custom call without a stable ABI: plain jit
        return None
    tmp = f"{path}.tmp-{os.getpid()}-{threading.get_ident()}"
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except OSError:  # a read-only cache: kept in memory only
        pass
    return _named_call(exported, fn)


def _named_call(exported, fn):
    """jax.jit of the exported program's call, named after fn, so that JAX's compile logs and
    profiles say which program it is (they would all read ``jit(call)``)."""
    def call(*xs):
        return exported.call(*xs)

    call.__name__ = call.__qualname__ = fn.__name__
    return jax.jit(call)
