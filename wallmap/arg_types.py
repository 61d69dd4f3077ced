"""Argument types shared by the ``wallmap`` subcommands: a bad value is one line from argparse."""

from __future__ import annotations

import argparse
import math


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


def port(value: str) -> int:
    """A TCP port, 0 for any free one."""
    number = int(value)
    if not 0 <= number <= 65535:
        msg = f"must be a TCP port 0-65535 (0 for any free one), got {value}"
        raise argparse.ArgumentTypeError(msg)
    return number
