"""``wallmap ros2``: a live ROS 2 robot's topics on Zenoh, as the player's frames and poses."""
