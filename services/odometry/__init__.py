"""The odometry service: robot poses estimated from the sensor frames themselves."""
