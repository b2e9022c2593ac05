"""Preloaded into a local cluster's Dask workers (``dask_setup``): Ctrl-C is the batch's.

A Ctrl-C at the terminal reaches every process of the batch.  The batch
process closes the cluster and says what was made; workers that took the
signal too printed tracebacks and went on writing runs after that.  They now
ignore it once started (workers started again after a crash too: the nanny
starts them with this preload).  A Ctrl-C while they are still starting (the
first second or so of a batch) still reaches them: it stops the batch all
the same, with their tracebacks.
"""

from __future__ import annotations

import signal
import threading


def dask_setup(worker) -> None:  # Dask's preload interface
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
