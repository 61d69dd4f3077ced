"""wallmap: map the walls of a building from a moving RGB-D sensor, as services over Zenoh.

In a checkout, ``wallmap/common`` and ``wallmap/services`` are symbolic links to the top-level
``common/`` and ``services/`` (the layout the project asks for); installed wheels and sdists carry
real folders. A clone made where git does not make symbolic links (Windows without Developer Mode,
``core.symlinks=false``) has small text files in their place, and every import of them would fail
far from the cause: this says so at once.
"""

from pathlib import Path

__version__ = "0.1.0"


def _check_links() -> None:
    here = Path(__file__).resolve().parent
    broken = [name for name in ("common", "services") if not (here / name).is_dir()]
    if broken:
        msg = (
            f"wallmap/{broken[0]} is not a folder: this checkout lost its symbolic links (a clone "
            "where git does not make them, such as Windows without Developer Mode). Clone with "
            "`git clone -c core.symlinks=true`, or install the package (`pip install .`), which "
            "copies the folders. Supported: Linux and macOS (docs/deployment.md)."
        )
        raise ImportError(msg)


_check_links()
