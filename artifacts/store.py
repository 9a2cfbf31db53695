"""Freezing and verifying `artifacts/<domain>/`: four sources under stable names + manifest.

Writes are atomic: the new set is written to a sibling temporary folder and swapped in with
renames, so a crash leaves either the old set or the new one, never a mix.

`eval.json` (the metrics `rivet eval DOMAIN --policy artifacts` writes, stamped with the set
hash it measured) never outlives its set under that name: freezing a different set moves it
aside to `eval.stale.json`, so the new set reads as not evaluated until it is. Should the new
set be one that `eval.stale.json` measured (a set frozen again after a revert), that file
becomes `eval.json` again.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

from artifacts.errors import ArtifactError
from artifacts.hashing import (
    CHECKED_AGAINST,
    REPO,
    changed_since_checked,
    checked_against,
    set_hash,
    sha256_bytes,
    sha256_text,
)
from contracts import ContractError, validate
from contracts.functions import FUNCTIONS, dependencies

ROOT = REPO / "artifacts"
EVAL = "eval.json"  # the metrics of the set in this folder, stamped with its set hash
STALE_EVAL = "eval.stale.json"  # metrics of an earlier set, moved aside by `freeze`


def domain_dir(domain: str, root: Path | None = None) -> Path:
    return (root or ROOT) / domain


def build_manifest(
    domain: str,
    sources: dict[str, str],
    *,
    author: dict[str, Any],
    prompt_hash: str | None = None,
    attempts: dict[str, int] | None = None,
    checks: dict[str, dict[str, int]] | None = None,
    cases_seeds: dict[str, int] | None = None,
) -> dict[str, Any]:
    functions: dict[str, Any] = {}
    for name in FUNCTIONS:
        if name not in sources:
            raise ArtifactError(f"cannot freeze {domain}: '{name}' has no passing draft")
        entry: dict[str, Any] = {
            "file": f"{name}.py",
            "sha256": sha256_text(sources[name]),
            "depends_on": list(dependencies(name)),
        }
        if attempts and name in attempts:
            entry["attempts"] = attempts[name]
        if checks and name in checks:
            entry["checks"] = checks[name]
        if cases_seeds and cases_seeds.get(name) is not None:
            entry["cases_seed"] = int(cases_seeds[name])
        functions[name] = entry
    manifest: dict[str, Any] = {
        "schema_version": 1,
        "domain": domain,
        "set_hash": set_hash({n: e["sha256"] for n, e in functions.items()}),
        "functions": functions,
        "author": author,
        **checked_against(),
        "created_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    if prompt_hash:
        manifest["prompt_hash"] = prompt_hash
    validate("manifest", manifest)
    return manifest


def freeze(
    domain: str, sources: dict[str, str], manifest: dict[str, Any], root: Path | None = None
) -> bool:
    """Write the set atomically; return False (writing nothing) when the set hash is unchanged
    and it was checked against the same contracts and toolbox. The same set checked again
    against a changed toolbox gets the new manifest (and keeps its `eval.json`)."""
    target = domain_dir(domain, root)
    current = target / "manifest.json"
    if current.is_file():
        try:
            old = json.loads(current.read_text())
        except json.JSONDecodeError:
            old = {}
        if isinstance(old, dict) and all(
            old.get(k) == manifest[k] for k in ("set_hash", *CHECKED_AGAINST)
        ):
            return False
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{domain}.new-"))
    try:
        if target.is_dir():  # keep files that are not part of the set (README, …)
            for p in target.iterdir():
                if p.is_file() and p.name not in {f"{n}.py" for n in FUNCTIONS} | {
                    "manifest.json",
                    EVAL,
                    STALE_EVAL,
                }:
                    shutil.copy2(p, tmp / p.name)
            _carry_eval(target, tmp, manifest["set_hash"])
        for name in FUNCTIONS:
            (tmp / f"{name}.py").write_text(sources[name], encoding="utf-8")
        (tmp / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")
        for p in tmp.iterdir():
            with open(p, "rb") as f:
                os.fsync(f.fileno())
        old = None
        if target.exists():
            old = target.with_name(f".{domain}.old-{os.getpid()}")
            os.replace(target, old)
        os.replace(tmp, target)
        if old is not None:
            shutil.rmtree(old)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
    return True


def stamped_set_hash(path: Path) -> str | None:
    """The `set_hash` a JSON file of a set stamps: the set an eval.json measured, or the one a
    manifest froze (None: no file, unreadable, or unstamped)."""
    try:
        value = json.loads(path.read_text()).get("set_hash")
    except (OSError, json.JSONDecodeError, AttributeError):
        return None
    return value if isinstance(value, str) else None


def _carry_eval(old: Path, new: Path, set_hash: str) -> None:
    """Into the new set's folder: as `eval.json` only metrics that measured `set_hash`; the
    latest metrics of another set as `eval.stale.json`."""
    current, stale = old / EVAL, old / STALE_EVAL
    if (
        stale.is_file()
        and stamped_set_hash(stale) == set_hash
        and stamped_set_hash(current) != set_hash
    ):
        current, stale = stale, current  # freezing again a set measured before: restore it
    if current.is_file():
        if stamped_set_hash(current) == set_hash:
            shutil.copy2(current, new / EVAL)
            if stale.is_file():
                shutil.copy2(stale, new / STALE_EVAL)
        else:
            shutil.copy2(current, new / STALE_EVAL)
    elif stale.is_file():
        shutil.copy2(stale, new / STALE_EVAL)


def verify(domain: str, root: Path | None = None) -> tuple[dict[str, Any], dict[str, str]]:
    """Check the manifest and every file's hash; return (manifest, sources). Raises ArtifactError."""
    target = domain_dir(domain, root)
    path = target / "manifest.json"
    if not path.is_file():
        raise ArtifactError(
            f"no frozen artifacts for '{domain}': {path} is missing (run: make author DOMAIN={domain})"
        )
    try:
        manifest = validate("manifest", json.loads(path.read_text()))
    except (json.JSONDecodeError, ContractError) as e:
        raise ArtifactError(f"{path}: invalid manifest: {e}") from None
    if manifest["domain"] != domain:
        raise ArtifactError(
            f"{path}: manifest is for domain '{manifest['domain']}', not '{domain}'"
        )
    sources: dict[str, str] = {}
    for name in FUNCTIONS:
        entry = manifest["functions"].get(name)
        if entry is None:
            raise ArtifactError(f"{path}: manifest lists no '{name}'")
        file = target / entry["file"]
        if not file.is_file():
            raise ArtifactError(f"{file} is missing")
        data = file.read_bytes()
        digest = sha256_bytes(data)
        if digest != entry["sha256"]:
            raise ArtifactError(
                f"{file}: sha256 {digest[:12]}… does not match the manifest's {entry['sha256'][:12]}…; "
                "refusing to load a modified artifact"
            )
        try:
            sources[name] = data.decode("utf-8")
        except UnicodeDecodeError:
            raise ArtifactError(f"{file} is not UTF-8 text") from None
    expected = set_hash({n: e["sha256"] for n, e in manifest["functions"].items()})
    if expected != manifest["set_hash"]:
        raise ArtifactError(f"{path}: set_hash does not match the functions' hashes")
    return manifest, sources


def unchecked_note(domain: str, manifest: dict[str, Any]) -> str | None:
    """A line for the user when the set's checks ran against other contracts or toolbox
    sources than this checkout's (None: they ran against these)."""
    trees = changed_since_checked(manifest)
    if not trees:
        return None
    return (
        f"note: artifacts/{domain} passed its checks against other sources of {'; '.join(trees)} "
        "than this checkout's; its programs run as frozen. Re-run their checks with "
        f"`pytest --rivet-artifacts artifacts/ -k 'manifest and {domain}'`; "
        f"`rivet author {domain}` re-stamps the set once they pass"
    )
