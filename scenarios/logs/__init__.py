"""Recorded data: real laser logs, recordings of runs, ROS 2 bags and extraction scores."""
