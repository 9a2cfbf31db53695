"""`make bench`: run every `benchmarks/*_bench.py` module's `main()`, in name order.

Usage: python -m benchmarks.run [NAME ...]   (e.g. `sandbox` runs only sandbox_bench)
"""

from __future__ import annotations

import importlib
import sys
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    wanted = set(sys.argv[1:] if argv is None else argv)
    names = sorted(p.stem for p in Path(__file__).parent.glob("*_bench.py"))
    if wanted:
        names = [n for n in names if n.removesuffix("_bench") in wanted or n in wanted]
    failed = []
    for name in names:
        print(f"== {name}", flush=True)
        t0 = time.perf_counter()
        rc = importlib.import_module(f"benchmarks.{name}").main()
        print(f"== {name}: done in {time.perf_counter() - t0:.1f} s (exit {rc or 0})\n", flush=True)
        if rc:
            failed.append(name)
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
