"""The graph's trial protocol (what the supervisor node runs, ROS-free): reset, push,
acknowledge, start, samples, done, its timing, and homing instead of a reset."""
