"""wallmap: map the walls of a building from a moving RGB-D sensor, as services over Zenoh."""

__version__ = "0.1.0"
