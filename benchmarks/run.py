"""Run every benchmark: ``python -m benchmarks.run [--quick] [--with-loop] [names...]`` (``make bench``).

Each benchmark module has ``run(quick: bool) -> dict`` and writes
results/bench/<name>.json itself; this runner prints one line per benchmark.
``loop`` (whole campaigns on the lab: hours in full, about an hour with --quick on
2 cores) and ``generalization`` (24 drawn lab setups, about 4 min each) are left out of the
default list: name them (``--with-loop`` adds the loop).
"""
from __future__ import annotations

import argparse
import importlib
import json
import time

BENCHMARKS = ("model_speed", "tracking", "sync", "estimation", "turnaround")
SLOW = ("loop", "generalization")   # run only when named (the loop also with --with-loop)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a short version of each")
    ap.add_argument("--with-loop", action="store_true", help="also run the slow `loop` benchmark")
    ap.add_argument("names", nargs="*", metavar="name", help=f"any of {', '.join(BENCHMARKS + SLOW)} "
                    f"(default: {', '.join(BENCHMARKS)})")
    args = ap.parse_args()
    unknown = sorted(set(args.names) - set(BENCHMARKS + SLOW))
    if unknown:
        ap.error(f"unknown benchmark(s) {', '.join(unknown)} (known: {', '.join(BENCHMARKS + SLOW)})")
    names = list(args.names or BENCHMARKS) + (["loop"] if args.with_loop and "loop" not in args.names else [])
    for name in names:
        t0 = time.perf_counter()
        doc = importlib.import_module(f"benchmarks.{name}").run(args.quick)
        keys = {k: v for k, v in doc.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
        print(f"{name} ({time.perf_counter() - t0:.0f} s): {json.dumps(keys)}")


if __name__ == "__main__":
    main()
