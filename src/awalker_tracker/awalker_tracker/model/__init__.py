"""Walker physics, cyclic gaits, control prior, conditional kinematics and body model (ROS-free)."""
