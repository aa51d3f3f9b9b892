"""A study's two directions run side by side (``run_all``), and stopped cleanly on an interrupt
(``Cancelled``): shared by the twist study, its diagram and its accuracy mode."""
from __future__ import annotations

import threading

__all__ = ["Cancelled", "run_all"]


class Cancelled(Exception):
    """Raised inside a direction's thread at a saved state once the main thread was interrupted."""


def run_all(run_direction, todo, parallel, cancel):
    """run_direction(*task) for each task, in threads when ``parallel`` and there are two; the
    first exception raised in a thread is raised here. Interrupted, the main thread sets
    ``cancel``, waits until every thread has stopped, and re-raises: no thread is left inside XLA
    at shutdown."""
    if not parallel or len(todo) < 2:
        for task in todo:
            run_direction(*task)
        return
    errors = []
    # waits on Events in short waits, not Thread.join: a join interrupted by Ctrl-C marks the thread stopped
    done = [threading.Event() for _ in todo]

    def target(task, finished):
        try:
            run_direction(*task)
        except Cancelled:
            pass
        except BaseException as exc:  # noqa: BLE001 -- handed to the main thread
            errors.append(exc)
        finally:
            finished.set()

    threads = [threading.Thread(target=target, args=(task, finished), daemon=True)
               for task, finished in zip(todo, done)]
    for t in threads:
        t.start()
    try:
        for finished in done:
            while not finished.wait(0.2):
                pass
    except BaseException:
        cancel.set()
        for finished in done:
            while not finished.wait(0.2):
                pass
        raise
    if errors:
        raise errors[0]
