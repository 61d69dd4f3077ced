"""The wallmap services: player, detector, mapper, odometry and merge, each a thin Zenoh shell.

Their method is pure code in common/ and in each service's own package; merge makes a fleet's map.
"""
