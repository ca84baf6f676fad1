#!/usr/bin/env python3
"""The `analyze` command (`ros2 run ato_nodes analyze`), run from the checkout; its code
and --help are in ato_nodes/cli/analyze.py."""

import _cli

if __name__ == "__main__":
    _cli.start("analyze")
