"""Independent jobs on a local process pool or a Dask cluster: the Monte-Carlo
grid points (analysis.montecarlo) and a fleet's logs (odomgraph.fleet) run
through here, so both behave alike: the same worker set-up, the same way to
stop, the same ``--workers`` and ``--scheduler tcp://HOST:PORT``.

Results arrive in completion order through ``finished(item, result)``. The
Monte-Carlo sweep writes each grid point as it comes, so an interrupted sweep
keeps what is done; a fleet writes its output directory once, at the end.
"""
from __future__ import annotations

import os

from odomgraph.errors import OdomgraphError


def run_jobs(fn, items: list, finished, workers: int | None = None, scheduler: str | None = None,
             client=None) -> None:
    """Call ``fn(item)`` for every item and ``finished(item, result)`` as each ends.

    ``scheduler``: a Dask scheduler address (tcp://HOST:PORT); ``client``: an
    existing dask.distributed.Client (tests pass a LocalCluster's). Otherwise
    a local pool of ``workers`` processes (default: all cores; 1 runs them in
    this process). ``fn`` must be a module-level function (it is pickled).
    An exception in a job propagates and stops the rest: a job that may fail
    returns its failure as a value instead.
    """
    if not items:
        return
    if client is not None or scheduler is not None:
        _run_dask(fn, items, scheduler, client, finished)
    else:
        _run_local(fn, items, workers, finished)


def worker_init(parent: int) -> None:
    """Set up a local worker: it leaves Ctrl-C and SIGTERM to the parent (which
    terminates the pool), and exits by itself when the parent is gone, even
    after a SIGKILL that gave the parent no chance to clean up."""
    import signal
    import threading
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:   # Linux: the kernel sends SIGTERM when the parent dies
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass

    def watch():
        import time
        while os.getppid() == parent:
            time.sleep(1.0)
        os._exit(1)
    threading.Thread(target=watch, daemon=True).start()
    if os.getppid() != parent:      # died before the watch started
        os._exit(1)


class _Indexed:
    """fn as a picklable callable of (index, item) -> (index, fn(item))."""

    def __init__(self, fn):
        self.fn = fn

    def __call__(self, pair):
        i, item = pair
        return i, self.fn(item)


def _run_local(fn, items, workers, finished):
    import multiprocessing as mp
    workers = workers or os.cpu_count() or 1
    if workers <= 1:
        for item in items:
            finished(item, fn(item))
        return
    pool = mp.get_context("fork").Pool(min(workers, len(items)), initializer=worker_init, initargs=(os.getpid(),))
    try:
        for i, r in pool.imap_unordered(_Indexed(fn), list(enumerate(items))):
            finished(items[i], r)
        pool.close()
    except BaseException:
        # Ctrl-C, SIGTERM (raised as KeyboardInterrupt by the CLI) or a failed
        # job: stop the workers now instead of waiting for their jobs.
        pool.terminate()
        raise
    finally:
        pool.join()


def _run_dask(fn, items, scheduler, client, finished):
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise OdomgraphError("--scheduler needs Dask: pip install 'odomgraph[dask]'") from None
    own = client is None
    if own:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise OdomgraphError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
    try:
        futures = client.map(fn, items, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        for f in as_completed(futures):
            finished(items[index[f.key]], f.result())
    finally:
        if own:
            client.close()
