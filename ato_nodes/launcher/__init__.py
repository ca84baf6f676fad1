"""Starting a run's node graph: the processes, the ROS domain lock, the nodes'
environment, and the fork server the nodes start from."""
