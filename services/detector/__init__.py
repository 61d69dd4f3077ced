"""The detector: finds walls in one row of each sensor frame."""
