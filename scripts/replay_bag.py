#!/usr/bin/env python3
"""The `replay_bag` command (`ros2 run ato_nodes replay_bag`), run from the checkout; its code
and --help are in ato_nodes/cli/replay_bag.py."""

import _cli

if __name__ == "__main__":
    _cli.start("replay_bag")
