"""The worked examples in the documentation run as written: each ```python block of the files
below is executed in a fresh namespace (the signature sketches elsewhere are not examples)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = [
    "docs/executor.md",
    "docs/api.md",
]  # docs/refine.md's runs in tests/toolbox/test_refine.py


def _blocks(path: Path) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", path.read_text(), re.S | re.M)


@pytest.mark.slow
@pytest.mark.parametrize("doc", EXAMPLES)
def test_the_examples_run_as_written(doc):
    blocks = _blocks(REPO / doc)
    assert blocks, f"{doc} has no python example"
    for k, block in enumerate(blocks):
        exec(compile(block, f"{doc} (example {k + 1})", "exec"), {"__name__": "example"})
