"""Algorithms of the ATO stack in plain Python/numpy; nothing here imports ROS."""
