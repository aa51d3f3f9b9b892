"""One run per output folder: an OS-level lock on a file in the folder.

Two studies writing into one folder interleave their rows and rename each other's temporary
files (seen: the first run died on a missing ``.tmp-state_minus.npz``, the second ended with 53
duplicate rows). ``folder_lock(folder)`` takes an exclusive ``flock`` on ``folder/.jaxrod.lock``
for as long as the ``with`` block runs. The operating system releases it when the process ends in
any way (``kill -9`` included), so a dead run never leaves the folder locked; a second process
asking for the same folder is refused at once with ``FolderInUseError``, which names the folder
and the process holding it. Within one process the lock is re-entrant (the CLI takes it before
compiling, ``twist_study`` again inside), and two threads of one process share it.
"""
from __future__ import annotations

import contextlib
import datetime
import json
import os
import sys
import threading

try:  # POSIX; elsewhere runs go unlocked (jaxrod is developed and tested on Linux)
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None

__all__ = ["FolderInUseError", "folder_lock", "holds_output_folder", "LOCK_NAME"]

LOCK_NAME = ".jaxrod.lock"

# The folders this process holds, with a count (re-entrant) and the open lock file: the only
# process-wide state of jaxrod, because a flock is owned by an open file, not by a caller.
_held: dict[str, list] = {}
_guard = threading.Lock()


class FolderInUseError(ValueError):
    """Another process holds the folder's lock: a run is writing there now."""


def _holder(path):
    try:
        with open(path) as f:
            info = json.load(f)
        return f" (pid {info['pid']}, started {info['started']}, command: {info['command']})"
    except (OSError, ValueError, KeyError, TypeError):
        return ""


@contextlib.contextmanager
def folder_lock(folder, what="out"):
    """Hold the exclusive lock of ``folder`` (created if missing) while the block runs; raise
    FolderInUseError naming ``what`` (the parameter: 'out') if another process holds it."""
    os.makedirs(folder, exist_ok=True)
    key = os.path.realpath(folder)
    with _guard:
        if key in _held:
            _held[key][0] += 1
        else:
            path = os.path.join(folder, LOCK_NAME)
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
            if fcntl is not None:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except OSError:
                    os.close(fd)
                    raise FolderInUseError(
                        f"{what} {folder} is in use by another jaxrod run{_holder(path)}: wait for it to end, "
                        "or use another folder") from None
            info = {"pid": os.getpid(), "started": datetime.datetime.now().isoformat(timespec="seconds"),
                    "command": " ".join(os.path.basename(a) if i == 0 else a for i, a in enumerate(sys.argv))}
            os.ftruncate(fd, 0)
            os.write(fd, json.dumps(info).encode())
            _held[key] = [1, fd]
    try:
        yield
    finally:
        with _guard:
            _held[key][0] -= 1
            if _held[key][0] == 0:
                fd = _held.pop(key)[1]
                if fcntl is not None:
                    fcntl.flock(fd, fcntl.LOCK_UN)
                os.close(fd)


def holds_output_folder(function):
    """Decorator: ``function`` runs holding ``folder_lock`` of its ``out`` argument (when not None)."""
    import functools
    import inspect

    signature = inspect.signature(function)

    @functools.wraps(function)
    def locked(*args, **kwargs):
        out = signature.bind(*args, **kwargs).arguments.get("out")
        with folder_lock(out) if out else contextlib.nullcontext():
            return function(*args, **kwargs)

    return locked
