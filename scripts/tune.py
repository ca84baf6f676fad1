#!/usr/bin/env python3
"""The `tune` command (`ros2 run ato_nodes tune`), run from the checkout; its code
and --help are in ato_nodes/cli/tune.py."""

import _cli

if __name__ == "__main__":
    _cli.start("tune")
