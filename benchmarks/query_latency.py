"""Latency of `{prefix}/map/walls` queries: real router, real mapper process, concurrent clients.

A map of about 1,000 walls (benchmarks/mapper_scaling.py's grid of rooms) is written as the
mapper's state file; the mapper serves it and N client sessions query it at once.

    .venv/bin/python benchmarks/query_latency.py [--walls 1000] [--clients 10] [--queries 100]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from mapper_scaling import build

from wallmap.common.codec import decode, encode
from wallmap.common.link_settings import ZenohSettings
from wallmap.common.map_requests import QueryError, fetch_map
from wallmap.common.transport import Keys, open_session
from wallmap.launcher import free_loopback_port
from wallmap.services.mapper import serving, state_file


def wait_for_map(settings: ZenohSettings, walls: int) -> None:
    deadline = time.monotonic() + 60
    with open_session(settings) as session:
        while time.monotonic() < deadline:
            try:
                if len(fetch_map(session, Keys(), timeout=2.0).walls) >= walls:
                    return
            except QueryError:  # the mapper is not up yet
                time.sleep(0.2)
    raise TimeoutError("the mapper never served the map")


def client(
    settings: ZenohSettings, queries: int, out: list[float], start: threading.Barrier
) -> None:
    """Time each query from request to the reply's bytes in hand (decoding is timed apart)."""
    with open_session(settings) as session:
        # One untimed query first: it sets up the session's routes (the mapper's encoding of a
        # changed map is timed apart: "rebuild ms").
        list(session.get(Keys().map_walls, timeout=5.0))
        start.wait()
        for _ in range(queries):
            begin = time.perf_counter()
            replies = [r.ok.payload.to_bytes() for r in session.get(Keys().map_walls, timeout=5.0)]
            out.append(time.perf_counter() - begin)
            assert replies, "no reply"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--walls", type=int, default=1000)
    parser.add_argument("--clients", type=int, default=10)
    parser.add_argument("--queries", type=int, default=100, help="per client")
    args = parser.parse_args()
    wall_map = build(args.walls, np.random.default_rng(0))
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    settings = ZenohSettings(connect=(endpoint,), wait_for_router=20.0)
    with tempfile.TemporaryDirectory() as tmp:
        state = Path(tmp) / "map.json"
        state_file.write(state, state_file.to_json(wall_map))
        wallmap = [sys.executable, "-m", "wallmap"]
        procs = [subprocess.Popen([*wallmap, "router", "--listen", endpoint])]
        procs.append(
            subprocess.Popen([*wallmap, "mapper", "--state", str(state), "--connect", endpoint])
        )
        try:
            wait_for_map(settings, len(wall_map.walls))
            latencies: list[list[float]] = [[] for _ in range(args.clients)]
            barrier = threading.Barrier(args.clients)
            threads = [
                threading.Thread(target=client, args=(settings, args.queries, out, barrier))
                for out in latencies
            ]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
        finally:
            for proc in reversed(procs):
                proc.terminate()
                proc.wait()
    begin = time.perf_counter()
    for _ in range(20):
        payload = encode(serving.reply(wall_map).to_map())
    rebuild_ms = (time.perf_counter() - begin) / 20 * 1e3
    begin = time.perf_counter()
    for _ in range(20):
        decode(payload)
    decode_ms = (time.perf_counter() - begin) / 20 * 1e3
    every = sorted(x for out in latencies for x in out)
    p99 = every[min(len(every) - 1, int(0.99 * len(every)))]
    print(
        f"{'walls':>6} {'clients':>8} {'queries':>8} {'p50 ms':>8} {'p99 ms':>8}"
        f" {'reply kB':>9} {'rebuild ms':>10} {'decode ms':>10}"
    )
    print(
        f"{len(wall_map.walls):>6} {args.clients:>8} {len(every):>8}"
        f" {statistics.median(every) * 1e3:>8.2f} {p99 * 1e3:>8.2f}"
        f" {len(payload) / 1e3:>9.0f} {rebuild_ms:>10.2f} {decode_ms:>10.2f}"
    )


if __name__ == "__main__":
    main()
