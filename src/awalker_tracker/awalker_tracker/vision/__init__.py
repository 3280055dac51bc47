"""Cameras, background/foreground appearance models, optical flow and the image likelihood (ROS-free)."""
