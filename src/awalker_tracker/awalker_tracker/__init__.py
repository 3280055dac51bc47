"""awalker_tracker: physics-based 3D person tracking with the Anthropomorphic Walker.

The core (``model``, ``vision``, ``inference``) is ROS-free; ``nodes`` holds thin rclpy nodes.
"""
from awalker_tracker.blocks import limit_blas_threads

limit_blas_threads()
