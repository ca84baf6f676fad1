"""Shared by the scripts: make the repo importable, then the helpers of ato_nodes.cli."""

import signal

# A Ctrl-C or SIGTERM during the imports below is held, not raised where it lands (a
# traceback) nor fatal (SIGTERM's default): handle_signals_while_starting() installs the
# handler, then lets it through.
signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})

import sys  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ato_nodes.cli import (argument_parser, fail, handle_signals_while_starting,  # noqa: E402,F401
                           interrupted_quietly, new_directory, seconds, start)

handle_signals_while_starting()  # before the script's own (slower) imports
