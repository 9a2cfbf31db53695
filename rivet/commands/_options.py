"""Options several commands share, defined once."""

from __future__ import annotations

import argparse

from sandbox import BACKENDS


def add_sandbox_option(parser: argparse.ArgumentParser, *, what: str = "the programs") -> None:
    """`--sandbox docker|local`: where model-written code runs. Docker is the default; the
    local backend isolates nothing (it says so) and is only ever used when named."""
    parser.add_argument(
        "--sandbox",
        choices=BACKENDS,
        default="docker",
        help=f"where {what} run: docker (default) or local (faster, isolates nothing)",
    )
