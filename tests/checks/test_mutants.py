"""The mutant catalogue applies to the current reference programs (each replacement exactly once)."""

from __future__ import annotations

from collections import Counter

from benchmarks.checks_bench import catalogue, load_mutants, programs


def test_catalogue_applies_and_covers_every_function():
    mutants = load_mutants(catalogue("cubes"), programs("cubes"))
    assert len(mutants) >= 30
    per_function = Counter(m.function for m in mutants)
    assert set(per_function) == {"render", "perceive", "relate", "plan"}
    for m in mutants:
        compile(m.source, f"{m.name}.py", "exec")  # every mutant is valid Python
