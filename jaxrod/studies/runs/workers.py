"""Jobs run by worker threads beside a study: a knot study's branch ends are located, and its
error estimate computed, as soon as the study has found them (``run_knot_study``)."""
from __future__ import annotations


class Workers:
    """Jobs run by worker threads in the order submitted (``submit``; one thread started at once
    unless start=False, more by ``add_worker``); ``results()`` waits for them all (in short waits,
    so that Ctrl-C reaches the main thread); ``stop()`` cancels. Thread-safe: the study's threads
    submit, the main thread collects."""

    def __init__(self, start=True):
        import collections
        import threading

        self._threading = threading
        self._jobs = collections.deque()
        self._wake = threading.Condition()
        self._cancel = threading.Event()
        self._closed = False
        self._values, self._errors, self._done = {}, [], []
        self.keys = set()
        if start:
            self.add_worker()

    @property
    def n_workers(self):
        return len(self._done)

    def submit(self, key, fn):
        """Queues the job fn(cancel) under ``key`` (cancel: a threading.Event set by ``stop``)."""
        with self._wake:
            self.keys.add(key)
            self._jobs.append((key, fn))
            self._wake.notify()

    def add_worker(self):
        """Starts one more worker thread."""
        done = self._threading.Event()
        self._done.append(done)

        def loop():
            try:
                while True:
                    with self._wake:
                        while not self._jobs and not self._closed:
                            self._wake.wait(0.2)
                        if not self._jobs:
                            return
                        key, fn = self._jobs.popleft()
                    if self._cancel.is_set():
                        continue
                    try:
                        self._values[key] = fn(self._cancel)
                    except BaseException as exc:  # noqa: BLE001 -- handed to the main thread
                        if not self._cancel.is_set():
                            self._errors.append(exc)
                        self._cancel.set()  # the first failure ends the others' work too
            finally:
                done.set()

        self._threading.Thread(target=loop, daemon=True).start()

    def _close(self):
        with self._wake:
            self._closed = True
            self._wake.notify_all()

    def _wait(self):
        for done in list(self._done):
            while not done.wait(0.2):
                pass

    def results(self):
        """{key: value} of every job, once all have run; raises the first job's exception."""
        self._close()
        try:
            self._wait()
        except BaseException:  # Ctrl-C while waiting: stop the threads first
            self.stop()
            raise
        if self._errors:
            raise self._errors[0]
        return dict(self._values)

    def stop(self):
        """Cancels the running jobs, drops the queued ones and waits for the threads."""
        self._cancel.set()
        with self._wake:
            self._jobs.clear()
        self._close()
        self._wait()
