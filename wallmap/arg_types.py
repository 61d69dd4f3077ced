"""Argument types shared by the ``wallmap`` subcommands: a bad value is one line from argparse."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from wallmap.services.ros2_source.settings import MAX_DOMAIN

PICTURE_SUFFIXES = (".png", ".svg")  # what ``wallmap.plot.write_picture`` draws


def positive(value: str) -> float:
    """A finite number > 0 (a rate, a timeout, a duration)."""
    x = float(value)
    if not math.isfinite(x) or x <= 0:
        msg = f"must be a positive number, got {value}"
        raise argparse.ArgumentTypeError(msg)
    return x


def non_negative(value: str) -> float:
    """A finite number >= 0 (an offset into a bag)."""
    x = float(value)
    if not math.isfinite(x) or x < 0:
        msg = f"must be a number >= 0, got {value}"
        raise argparse.ArgumentTypeError(msg)
    return x


def robot_prefixes(value: str) -> list[str]:
    """``A,B[,...]``: two or more distinct robot prefixes (the first one's frame is the fleet's)."""
    robots = [part.strip() for part in value.split(",")]
    if len(robots) < 2 or not all(robots) or len(set(robots)) != len(robots):
        msg = f"must be two or more distinct robot prefixes, A,B[,...], got {value!r}"
        raise argparse.ArgumentTypeError(msg)
    return robots


def port(value: str) -> int:
    """A TCP port, 0 for any free one."""
    number = int(value)
    if not 0 <= number <= 65535:
        msg = f"must be a TCP port 0-65535 (0 for any free one), got {value}"
        raise argparse.ArgumentTypeError(msg)
    return number


def finite(value: str) -> float:
    """Any finite number (a height, which may lie below the frame's origin)."""
    x = float(value)
    if not math.isfinite(x):
        msg = f"must be a finite number, got {value}"
        raise argparse.ArgumentTypeError(msg)
    return x


def intrinsics(value: str) -> tuple[float, float, float, float]:
    """A pinhole camera as FX,FY,CX,CY in pixels (focal lengths positive)."""
    try:
        fx, fy, cx, cy = (float(v) for v in value.split(","))
    except ValueError:
        msg = f"expected FX,FY,CX,CY in pixels, got {value!r}"
        raise argparse.ArgumentTypeError(msg) from None
    if not all(map(math.isfinite, (fx, fy, cx, cy))) or fx <= 0 or fy <= 0:
        msg = f"FX,FY must be positive and all four finite, got {value!r}"
        raise argparse.ArgumentTypeError(msg)
    return fx, fy, cx, cy


def planar_pose(value: str) -> tuple[float, float, float]:
    """A planar pose as X,Y,YAW (metres, radians), all finite."""
    try:
        x, y, yaw = (float(v) for v in value.split(","))
    except ValueError:
        msg = f"expected X,Y,YAW (metres, radians), got {value!r}"
        raise argparse.ArgumentTypeError(msg) from None
    if not all(map(math.isfinite, (x, y, yaw))):
        msg = f"X,Y,YAW must be finite, got {value!r}"
        raise argparse.ArgumentTypeError(msg)
    return x, y, yaw


def band(value: str) -> tuple[float, float]:
    """A height band as LOW,HIGH in metres, low below high."""
    try:
        low, high = (float(v) for v in value.split(","))
    except ValueError as err:
        msg = f"expected LOW,HIGH in metres, got {value!r}"
        raise argparse.ArgumentTypeError(msg) from err
    if not low < high:
        msg = f"LOW must be below HIGH, got {value!r}"
        raise argparse.ArgumentTypeError(msg)
    return low, high


def picture_problem(path: Path) -> str | None:
    """Why ``path`` cannot be a picture (.png or .svg, the two kinds ``wallmap.plot`` draws)."""
    if path.suffix.lower() in PICTURE_SUFFIXES:
        return None
    return f"a picture is drawn as .png or .svg, not {path.suffix or 'a file without a suffix'}"


def picture(value: str) -> Path:
    """A picture's file name (``picture_problem``)."""
    problem = picture_problem(Path(value))
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return Path(value)


def positive_int(value: str) -> int:
    """A whole number > 0 (a size in pixels)."""
    number = int(value)
    if number <= 0:
        msg = f"must be a whole number > 0, got {value}"
        raise argparse.ArgumentTypeError(msg)
    return number


def domain_id(value: str) -> int:
    """A ROS domain id: a whole number 0-232."""
    number = int(value)
    if not 0 <= number <= MAX_DOMAIN:
        msg = f"must be a ROS domain id, 0-{MAX_DOMAIN}, got {value}"
        raise argparse.ArgumentTypeError(msg)
    return number
