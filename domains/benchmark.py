"""Write or verify a domain's fixed benchmark set (20 goals × 3 starts).

    python -m domains.benchmark cubes            # (re)write domains/cubes/benchmark/*.json
    python -m domains.benchmark cubes --check    # exit 1 if regeneration differs

Generation is deterministic: goal g is drawn from the seed (10000, g), its starts from
(10000, g, s); goal 1 is the domain's hand-authored reference.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Sequence

import numpy as np

import domains
from domains.base import BENCHMARK_GOALS, BENCHMARK_STARTS, Domain, Instance

_NUMBERS = re.compile(r"\[\s*(-?[\d.e+-]+(?:,\s*-?[\d.e+-]+)*)\s*\]")


def dumps(value: dict) -> str:
    """JSON with every list of numbers (a pose row) on one line: reviewable diffs."""
    text = json.dumps(value, indent=1)
    text = _NUMBERS.sub(
        lambda m: "[" + ", ".join(v.strip() for v in m.group(1).split(",")) + "]", text
    )
    return text + "\n"


def regenerate(domain: Domain) -> list[Instance]:
    return [
        domain.benchmark_instance(g, s)
        for g in range(1, BENCHMARK_GOALS + 1)
        for s in range(1, BENCHMARK_STARTS + 1)
    ]


def same(a: dict, b: dict, atol: float = 1e-7) -> bool:
    """JSON instances equal up to `atol` in every number."""
    if type(a) is not type(b):
        return isinstance(a, int | float) and isinstance(b, int | float) and abs(a - b) <= atol
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k], atol) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(same(x, y, atol) for x, y in zip(a, b, strict=True))
    if isinstance(a, float):
        return bool(np.isclose(a, b, rtol=0, atol=atol))
    return a == b


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("domain", choices=domains.names())
    parser.add_argument("--check", action="store_true", help="compare instead of writing")
    args = parser.parse_args(argv)
    domain = domains.load(args.domain)
    domain.benchmark_dir.mkdir(exist_ok=True)
    differ = []
    for inst in regenerate(domain):
        path = domain.benchmark_dir / f"{inst.name}.json"
        value = inst.to_dict()
        if args.check:
            if not path.exists() or not same(json.loads(path.read_text()), value):
                differ.append(inst.name)
        else:
            path.write_text(dumps(value))
            print(f"{path}: {len(inst.order)} steps")
    if differ:
        print(f"{args.domain}: regenerated instances differ: {', '.join(differ)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
