#!/usr/bin/env python3
"""The `run_stack` command (`ros2 run ato_nodes run_stack`), run from the checkout; its code
and --help are in ato_nodes/cli/run_stack.py."""

import _cli

if __name__ == "__main__":
    _cli.start("run_stack")
