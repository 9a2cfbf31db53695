"""Benchmarks: `make bench` runs every `*_bench.py` module's `main()` (see `run.py`)."""
