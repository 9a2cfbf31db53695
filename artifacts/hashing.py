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


def tree_hash(package: str, patterns: tuple[str, ...] = ("*.py", "*.json", "*.md")) -> str:
    """sha256 over a package's source files (relative path + bytes), e.g. `contracts`, `toolbox`."""
    root = REPO / package
    h = hashlib.sha256()
    files = sorted({p for pat in patterns for p in root.rglob(pat) if "__pycache__" not in p.parts})
    for p in files:
        h.update(str(p.relative_to(REPO)).encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()
