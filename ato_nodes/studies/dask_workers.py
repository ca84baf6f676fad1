"""What the worker processes of a LocalCluster (--cluster local:N) need from the study that
started them; imported only with Dask."""

from __future__ import annotations

import signal

from distributed.diagnostics.plugin import WorkerPlugin


class StopsAreTheStudys(WorkerPlugin):
    """A LocalCluster's worker processes share the study's terminal: a Ctrl-C there
    reaches them too, and is the study's to handle (it stops, cancels and closes the
    cluster, in one line). They ignore it, and SIGTERM (the cluster closing them) ends
    them quietly: started by importing the study's script, they would otherwise have
    its start-up handlers, each printing `interrupted`."""

    name = "ato-stops-are-the-studys"

    def setup(self, worker) -> None:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
