"""The player's allocator tuning applies where glibc is, and is harmless elsewhere."""

import platform

import pytest

from wallmap.common.allocator import keep_large_buffers


def test_keep_large_buffers_applies_on_glibc() -> None:
    if platform.libc_ver()[0] != "glibc":
        pytest.skip(f"no glibc here ({platform.libc_ver()}): the tuning is skipped by design")
    assert keep_large_buffers() is True
    assert keep_large_buffers() is True  # idempotent
