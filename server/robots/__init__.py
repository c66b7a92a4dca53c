"""Robots reached from outside srlab: a `World` over a ROS 2 robot's topics (`ros2`).

The robot file that says which topic feeds which channel is data, parsed in the core
(`core.sim.robotfile`); this room holds what talks to the robot (threads, the wall clock,
rclpy from the optional srlab[ros2] extra).
"""
