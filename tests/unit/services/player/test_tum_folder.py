"""A TUM folder's depth units when not given: what its depth.txt says, else what its depths say."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from wallmap.services.player.tum_folder import (
    MILLIMETRES,
    TUM_DEPTH_SCALE,
    folder_depth_scale,
)


def _folder(tmp_path: Path, header: str, depth_m: float, per_metre: float) -> tuple[Path, Path]:
    """A one-image folder: a wall ``depth_m`` away, written at ``per_metre`` units."""
    tmp_path.mkdir()
    image = tmp_path / "depth.png"
    raw = np.full((4, 6), round(depth_m * per_metre), np.uint16)
    raw[0, 0] = 0  # no return
    Image.fromarray(raw).save(image)
    listing = tmp_path / "depth.txt"
    listing.write_text(f"{header}\n1.0 depth.png\n")
    return listing, image


def test_the_header_or_the_depths_say_millimetres_else_tum_s_5000(tmp_path: Path) -> None:
    said = _folder(tmp_path / "said", "# depth maps (16-bit PNG, millimetres)", 0.3, MILLIMETRES)
    assert folder_depth_scale(*said) == (MILLIMETRES, None)  # the header wins, even so near
    tum = _folder(tmp_path / "tum", "# depth maps", 2.5, TUM_DEPTH_SCALE)
    assert folder_depth_scale(*tum) == (TUM_DEPTH_SCALE, None)
    scale, note = folder_depth_scale(*_folder(tmp_path / "mm", "# depth maps", 2.0, MILLIMETRES))
    assert scale == MILLIMETRES
    assert note is not None
    assert "within 0.40 m" in note
    assert "--depth-scale" in note
