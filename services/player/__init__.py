"""The player: plays ROS 1 and ROS 2 bags as sensor frames and poses over Zenoh."""
