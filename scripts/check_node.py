#!/usr/bin/env python3
"""The `check_node` command (`ato-check-node`, `ros2 run ato_nodes check_node`), run from the
checkout; its code and --help are in ato_nodes/cli/check_node.py."""

import _cli

if __name__ == "__main__":
    _cli.start("check_node")
