"""The Dask worker plugin of doefab's local clusters (imported only where ``dask.distributed`` is used).

A terminal's Ctrl-C reaches every process of its group: the local cluster's workers, which caught it each
printed a traceback beside the one line the interrupted command prints. Like the process pool's workers
(``montecarlo._worker_init``), they ignore it: the command stops, keeps the finished parts and closes them.
"""

from __future__ import annotations

from distributed.diagnostics.plugin import WorkerPlugin

__all__ = ["IgnoreCtrlC"]


class IgnoreCtrlC(WorkerPlugin):
    """Set SIGINT to be ignored in each worker process (in its main thread, where signals are set).

    Example: ``client.register_plugin(IgnoreCtrlC())`` on a ``LocalCluster``'s client."""

    name = "doefab-ignore-ctrl-c"

    def setup(self, worker) -> None:
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)
