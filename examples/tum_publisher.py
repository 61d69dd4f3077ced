"""Stream a TUM trajectory on wallmap's pose key in real time: an outside pose source.

Any program can be wallmap's pose source by publishing msgpack maps on ``{prefix}/pose``; this one
replays a TUM file (``t x y z qx qy qz qw``) with its recorded timing, scaled by ``--rate``. It uses
only zenoh and msgpack, to show exactly what goes on the wire. Run it beside
``wallmap player BAG --pose-source none --rate R`` with the same rate:

    python examples/tum_publisher.py trajectory.tum --rate 4
"""

import argparse
import json
import math
import time

import msgpack
import zenoh


def read_tum(path: str) -> list[tuple[float, float, float, float]]:
    """(stamp, x, y, yaw) per line; yaw from the quaternion (scalar last), assuming level motion."""
    poses = []
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.strip() and not line.startswith("#"):
                t, x, y, _z, qx, qy, qz, qw = map(float, line.split())
                yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
                poses.append((t, x, y, yaw))
    return poses


def main() -> None:
    """Parse flags, wait for the mapper to subscribe, then publish every pose on time."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tum", help="TUM trajectory file")
    parser.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1)")
    parser.add_argument("--connect", default="tcp/127.0.0.1:7447", help="Zenoh router")
    parser.add_argument("--prefix", default="wallmap", help="wallmap key prefix")
    args = parser.parse_args()

    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([args.connect]))
    config.insert_json5("scouting/multicast/enabled", "false")
    poses = read_tum(args.tum)
    with zenoh.open(config) as session:
        publisher = session.declare_publisher(
            f"{args.prefix}/pose", congestion_control=zenoh.CongestionControl.BLOCK
        )
        while not publisher.matching_status.matching:  # nobody listens yet: wait for the mapper
            time.sleep(0.05)
        start, first = time.monotonic(), poses[0][0]
        for stamp, x, y, yaw in poses:
            time.sleep(max(0.0, start + (stamp - first) / args.rate - time.monotonic()))
            pose = {
                "v": 1,
                "stamp": stamp,
                "frame": "map",
                "child": "base_link",
                "x": x,
                "y": y,
                "yaw": yaw,
            }
            publisher.put(msgpack.packb(pose))
        print(f"published {len(poses)} poses")


if __name__ == "__main__":
    main()
