"""What a recording's file says about itself, for ``wallmap doctor``, read without rosbags.

A bag the player cannot open still has a size, a magic line and (a ROS 1 bag) a header record
saying where its index should be: the doctor reports those first, so a damaged or misnamed bag
is told apart from one that is not a bag at all.
"""

from pathlib import Path

from wallmap.doctor_facts import FileFacts
from wallmap.services.player.errors import PlayerError
from wallmap.services.player.ros1_records import record_header

FORMATS = {
    b"#ROSBAG V2.0": "ros1",
    b"\x89MCAP": "ros2-mcap",
    b"SQLite format 3\x00": "ros2-sqlite3",
}
SUFFIXES = {"ros1": ".bag", "ros2-mcap": ".mcap", "ros2-sqlite3": ".db3"}
HEADER_COUNTS = {"index_pos", "conn_count", "chunk_count"}  # the bag header's fields reported


def _ros1_header(head: bytes) -> dict[str, int] | None:
    """The header record of a ROS 1 bag 2.0 (index position, chunk and connection counts).

    It is the one part of a damaged bag that still says what the recorder meant to write; a
    header that is damaged too says nothing (None).
    """
    pos = head.find(b"\n") + 1
    if pos == 0:
        return None
    try:
        fields, _ = record_header(head, pos)
    except PlayerError:
        return None
    counts = {
        name: int.from_bytes(value, "little")
        for name, value in fields.items()
        if name in HEADER_COUNTS
    }
    return counts or None


def file_facts(path: Path) -> FileFacts:
    """What the bag's file (or folder) says about itself, without rosbags.

    Raises:
        PlayerError: The path does not exist (the player's own message).
        OSError: The file cannot be read.
    """
    if not path.exists():
        raise PlayerError(f"bag not found: {path}")
    data = path
    if path.is_dir():
        files = [f for f in sorted(path.iterdir()) if f.is_file()]
        size = sum(f.stat().st_size for f in files)
        data = next((f for f in files if f.suffix in {".mcap", ".db3"}), path)
        if data == path:
            return FileFacts(size, "", None, name_matches=False)
    else:
        size = path.stat().st_size
    with data.open("rb") as file:
        head = file.read(4096)
    fmt = next((name for magic, name in FORMATS.items() if head.startswith(magic)), None)
    first_line = head.split(b"\n", 1)[0][:40]
    magic = "".join(chr(b) if 32 <= b < 127 else "." for b in first_line)
    if fmt is None:
        matches = False
    elif path.is_dir():  # rosbags finds a folder's storage through its metadata.yaml
        matches = fmt != "ros1" and (path / "metadata.yaml").is_file()
    else:  # and a file's format through its name
        matches = path.suffix == SUFFIXES[fmt]
    return FileFacts(size, magic, fmt, matches, _ros1_header(head) if fmt == "ros1" else None)
