"""Recorded runs: rosbag2 bags read into series, written as the recorder writes them,
repaired after a killed writer, and the summary.json beside them."""
