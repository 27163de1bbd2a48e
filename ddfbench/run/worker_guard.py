"""A local worker process ends when the sweep that started it is gone.

joblib's loky workers (hydra/launcher=local_parallel) are child processes of the sweep. When the sweep
is killed (`kill PID`, a session that ends) a worker in the middle of a job is re-parented and goes on
computing: an orphan that keeps writing the fit checkpoint of a run the next sweep resumes, beside
that sweep's own job of the same key. A worker that watches its parent ends within `poll_s` seconds of
it instead, without a record (a record is written atomically, so none is half written); its fit
checkpoint stays, and the next sweep goes on from it.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
import threading
import time

THREAD = "ddfbench-launcher-watch"
WORKER_PREFIX = "LokyProcess"  # joblib's process-based workers


def watch_launcher(poll_s: float = 2.0, worker_prefix: str = WORKER_PREFIX) -> bool:
    """In a worker process (its name starts with worker_prefix), start, once, a daemon thread that exits
    the process (status 143, as SIGTERM) when its parent process is gone; True if this process is watched."""
    if not multiprocessing.current_process().name.startswith(worker_prefix):
        return False
    if any(t.name == THREAD for t in threading.enumerate()):
        return True
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_s)
        print(f"ddfbench: worker {os.getpid()}: its sweep (process {parent}) is gone: the job stops, "
              "its fit checkpoint stays", file=sys.stderr, flush=True)
        os._exit(143)

    threading.Thread(target=watch, name=THREAD, daemon=True).start()
    return True
