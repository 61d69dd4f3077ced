"""The merge service: several robots' maps as one, in the first robot's frame (a fleet)."""
