"""`make bench`: run every `benchmarks/*_bench.py` module's `main()`, in name order.

Usage: python -m benchmarks.run [NAME ...]   (e.g. `sandbox` runs only sandbox_bench)
A benchmark that raises is reported and the others still run; the exit code is 1 if any failed.
Each `main()` is called with no arguments and `sys.argv` holding only its module name.
"""

from __future__ import annotations

import importlib
import sys
import time
import traceback
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    wanted = set(sys.argv[1:] if argv is None else argv)
    names = sorted(p.stem for p in Path(__file__).parent.glob("*_bench.py"))
    if wanted:
        names = [n for n in names if n.removesuffix("_bench") in wanted or n in wanted]
    failed = []
    saved_argv = sys.argv
    for name in names:
        print(f"== {name}", flush=True)
        t0 = time.perf_counter()
        sys.argv = [f"benchmarks.{name}"]
        try:
            rc = importlib.import_module(f"benchmarks.{name}").main()
        except Exception:
            traceback.print_exc()
            rc = 1
        finally:
            sys.argv = saved_argv
        print(f"== {name}: done in {time.perf_counter() - t0:.1f} s (exit {rc or 0})\n", flush=True)
        if rc:
            failed.append(name)
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
