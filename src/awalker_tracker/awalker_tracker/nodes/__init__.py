"""Thin rclpy nodes: features, tracker, pose publisher."""
