"""Shared by the scripts: make the repo importable, then the helpers of ato_nodes.cli."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ato_nodes.cli import (argument_parser, fail, handle_signals_while_starting,  # noqa: E402,F401
                           interrupted_quietly,
                           new_directory, seconds, start)

handle_signals_while_starting()  # before the script's own (slower) imports
