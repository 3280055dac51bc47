"""Particle filter with look-ahead, MAP trajectory and camera synchronisation (ROS-free)."""
