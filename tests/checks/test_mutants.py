"""Every domain's mutant catalogue applies to the current reference programs (each replacement
exactly once), covers all four functions and yields valid Python."""

from __future__ import annotations

import tomllib
from collections import Counter

import pytest

from benchmarks.checks_bench import DOMAINS, catalogue, load_mutants, programs

AT_LEAST = {"cubes": 30, "tangram": 15, "assembly": 15}


@pytest.mark.parametrize("domain", DOMAINS)
def test_catalogue_applies_and_covers_every_function(domain):
    path = catalogue(domain)
    data = tomllib.loads(path.read_text())
    assert data["domain"] == domain
    refs = programs(domain)
    for m in data["mutant"]:  # each `old` text occurs exactly once in its reference
        for old, _new in m["replace"]:
            assert refs[m["function"]].count(old) == 1, f"{m['name']}: {old[:60]!r}"
    mutants = load_mutants(path, refs)
    assert len(mutants) >= AT_LEAST[domain]
    per_function = Counter(m.function for m in mutants)
    assert set(per_function) == {"render", "perceive", "relate", "plan"}
    for m in mutants:
        assert m.bug and m.description
        compile(m.source, f"{m.name}.py", "exec")  # every mutant is valid Python
