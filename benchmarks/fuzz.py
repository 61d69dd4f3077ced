"""Mutation fuzzing of every decoder the services run on received bytes, and the crash count.

.venv/bin/python benchmarks/fuzz.py [--messages 100000] [--seed 0]
"""

from __future__ import annotations

import argparse
import time
import warnings

from wallmap.fuzzing import fuzz


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=100_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    warnings.simplefilter("ignore")  # numpy warns of overflows in absurd values it refuses
    start = time.perf_counter()
    outcomes = fuzz(args.messages, args.seed)
    seconds = time.perf_counter() - start
    print(f"{'decoder':<50} {'messages':>9} {'accepted':>9} {'refused':>9} {'crashes':>8}")
    for name, o in outcomes.items():
        crashes = sum(o.crashes.values())
        print(f"{name:<50} {o.messages:>9} {o.accepted:>9} {o.refused:>9} {crashes:>8}")
        for kind, n in o.crashes.items():
            print(f"    {n} x {kind}")
    total = sum(o.messages for o in outcomes.values())
    crashes = sum(sum(o.crashes.values()) for o in outcomes.values())
    print(f"{total} messages in {seconds:.1f} s, {crashes} crashes")


if __name__ == "__main__":
    main()
