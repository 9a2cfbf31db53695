"""Hashes recorded in a manifest: files, the program set, and the code the programs rely on."""

from __future__ import annotations

import ast
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
    """sha256 over what the packages' source files can change of behaviour (relative path +
    `behaviour_bytes`), e.g. `contracts`."""
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
        h.update(str(p.relative_to(REPO)).encode() + b"\0" + behaviour_bytes(p) + b"\0")
    return h.hexdigest()


def behaviour_bytes(path: Path) -> bytes:
    """What of a source file can change what code does: a Python module's syntax tree with
    its docstrings removed (comments and formatting are not in it), a JSON file's canonical
    form, any other file's bytes. What the prompts show of the code (the toolbox's public
    docstrings) is hashed apart, as the documentation (`toolbox_docs_hash`)."""
    text = path.read_bytes()
    if path.suffix == ".py":
        tree = ast.parse(text, filename=str(path))
        for node in ast.walk(tree):
            if isinstance(
                node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef
            ) and _has_docstring(node):
                node.body = node.body[1:] or [ast.Pass()]
        return ast.dump(tree, include_attributes=False).encode()
    if path.suffix == ".json":
        return json.dumps(json.loads(text), sort_keys=True, separators=(",", ":")).encode()
    return text


def _has_docstring(node: ast.AST) -> bool:
    body = getattr(node, "body", [])
    return bool(
        body
        and isinstance(body[0], ast.Expr)
        and isinstance(body[0].value, ast.Constant)
        and isinstance(body[0].value.value, str)
    )


def toolbox_docs_hash() -> str:
    """sha256 of the toolbox documentation the prompts show (`toolbox.docs.toolbox_docs`,
    built from the public docstrings)."""
    from toolbox.docs import toolbox_docs

    return sha256_text(toolbox_docs())


# What a frozen set passed its checks against (the manifest's `contracts_hash` and
# `toolbox_hash`): the contracts its arguments and results obey, and the code its programs
# call — the toolbox with the layer it stands on (`toolbox.robot.Hand` is `geometry.moves`).
CHECKED_AGAINST = {"contracts_hash": ("contracts",), "toolbox_hash": ("toolbox", "geometry")}


def robot_hash() -> str:
    """sha256 of the robot description in force (`geometry.robot.ROBOT`, which `RIVET_ROBOT`
    may name a file for): the hand a set was checked against."""
    from geometry.robot import ROBOT

    return sha256_text(json.dumps(ROBOT.to_json(), sort_keys=True))


def checked_against() -> dict[str, str]:
    """The current `contracts_hash` and `toolbox_hash` of this checkout: the toolbox hash
    covers the code's behaviour, the documentation the prompts show of it and the robot
    description in force."""
    out = {key: tree_hash(*trees) for key, trees in CHECKED_AGAINST.items()}
    out["toolbox_hash"] = sha256_text(out["toolbox_hash"] + toolbox_docs_hash() + robot_hash())
    return out


def changed_since_checked(manifest: dict) -> list[str]:
    """The trees (e.g. `toolbox/ and geometry/`) that changed since `manifest`'s set passed its
    checks."""
    now = checked_against()
    return [
        " and ".join(f"{t}/" for t in CHECKED_AGAINST[k])
        for k in CHECKED_AGAINST
        if manifest.get(k) != now[k]
    ]
