"""Hashes recorded in a manifest: files, the program set, and the code the programs rely on."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_text(text: str) -> str:
    return sha256_bytes(text.encode())


def set_hash(file_hashes: Mapping[str, str]) -> str:
    """sha256 over the sorted (function, file sha256) pairs: the identity of a program set."""
    return sha256_text(json.dumps(sorted(file_hashes.items())))


def tree_hash(*packages: str, patterns: tuple[str, ...] = ("*.py", "*.json", "*.md")) -> str:
    """sha256 over the packages' source files (relative path + bytes), e.g. `contracts`."""
    h = hashlib.sha256()
    files = sorted(
        {
            p
            for package in packages
            for pat in patterns
            for p in (REPO / package).rglob(pat)
            if "__pycache__" not in p.parts
        }
    )
    for p in files:
        h.update(str(p.relative_to(REPO)).encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


# What a frozen set passed its checks against (the manifest's `contracts_hash` and
# `toolbox_hash`): the contracts its arguments and results obey, and the code its programs
# call — the toolbox with the layer it stands on (`toolbox.robot.Hand` is `geometry.hand`).
CHECKED_AGAINST = {"contracts_hash": ("contracts",), "toolbox_hash": ("toolbox", "geometry")}


def checked_against() -> dict[str, str]:
    """The current `contracts_hash` and `toolbox_hash` of this checkout."""
    return {key: tree_hash(*trees) for key, trees in CHECKED_AGAINST.items()}


def changed_since_checked(manifest: dict) -> list[str]:
    """The trees (e.g. `toolbox/ and geometry/`) that changed since `manifest`'s set passed its
    checks."""
    now = checked_against()
    return [
        " and ".join(f"{t}/" for t in CHECKED_AGAINST[k])
        for k in CHECKED_AGAINST
        if manifest.get(k) != now[k]
    ]
