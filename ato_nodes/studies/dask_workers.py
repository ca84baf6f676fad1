"""What the worker processes of a Dask cluster need from the study that started them:
its plug-ins importable (checked as the cluster opens), and, for a LocalCluster's
(--cluster local:N), its terminal's stops left to the study; imported only with Dask."""

from __future__ import annotations

import signal

from distributed.diagnostics.plugin import WorkerPlugin

from ato_nodes.core.base.errors import ScenarioError
from ato_nodes.core.config import plugins
from ato_nodes.core.config.schema import load_plugins


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


def check_plugins(client, named: tuple[str, ...] | None = None) -> None:
    """Every worker of the cluster imports the study's plug-ins (default: those of the
    runs this process checked, plugins.in_use()) now; ScenarioError (one line) naming
    the first worker that cannot, before any run is handed out (its runs would each be
    refused there)."""
    named = plugins.in_use() if named is None else named
    if not named:
        return
    for address, refused in sorted(client.run(importing, named).items()):
        if refused:
            raise ScenarioError(f"Dask worker {address} cannot import the study's plug-ins: "
                                f"{refused} (install them where the workers run)")


def importing(named: tuple[str, ...]) -> str:
    """On a worker: its plug-ins imported; what refused one, or ''."""
    try:
        load_plugins(tuple(named))
    except ScenarioError as exc:
        return str(exc)
    return ""
