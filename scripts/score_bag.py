#!/usr/bin/env python3
"""The `score_bag` command (`ros2 run ato_nodes score_bag`), run from the checkout; its code
and --help are in ato_nodes/cli/score_bag.py."""

import _cli

if __name__ == "__main__":
    _cli.start("score_bag")
