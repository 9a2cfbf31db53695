"""The sandbox image: what goes into it, its hash tag, and an offline-capable build.

Design rule: the tag is the hash of the build inputs taken from the repository (Dockerfile,
pinned requirements, the harness, `contracts` and `toolbox`), so a change to any of them
rebuilds the image and nothing else does. The base image is recorded as a label, not hashed:
the public slim image and the debootstrap base are both Debian bookworm + Python 3.11, so one
repository state has one tag online and offline. Wheels come from a host-side wheelhouse
(downloaded from the URLs in uv.lock and checked against their hashes); nothing in the build
reaches a Python package index.

Usage: python -m sandbox.image {build [--base IMAGE] [--rebuild] | tag | prune | lock [--check]}
"""

from __future__ import annotations

import argparse
import concurrent.futures
import fcntl
import gc
import hashlib
import os
import re
import shutil
import ssl
import subprocess
import sys
import time
import tomllib
import urllib.parse
import urllib.request
import warnings
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from sandbox.errors import ImageBuildError, SandboxUnavailable

IMAGE_REPO = "rivet-sandbox"
ONLINE_BASE = "python:3.11-slim-bookworm"
OFFLINE_BASE = os.environ.get("RIVET_SANDBOX_BASE_TAG", "rivet-sandbox-base:bookworm")
LABEL = "rivet.sandbox"
# What the image's Python needs; their dependency closure is taken from uv.lock.
ROOT_PACKAGES = (
    "numpy",
    "scipy",
    "opencv-python-headless",
    "open3d",
    "trimesh",
    "networkx",
    "pyrender",
    "pyopengl",
    "hypothesis",
    "jsonschema",
    "pillow",
)
# The project's own packages copied into the image (pure Python, part of the hash).
PROJECT_PACKAGES = ("contracts", "geometry", "toolbox")
SANDBOX_DIR = Path(__file__).resolve().parent
REPO = SANDBOX_DIR.parent
REQUIREMENTS = SANDBOX_DIR / "requirements.txt"
CACHE = Path(os.environ.get("RIVET_CACHE", REPO / ".cache")) / "sandbox"
_STUB = '"""In-image stub: only `sandbox.harness` is present inside the sandbox image."""\n'
# The target the wheels are chosen for: the image's CPython 3.11 on Debian bookworm x86_64.
_MARKER_ENV = {
    "python_version": "3.11",
    "python_full_version": "3.11.2",
    "implementation_name": "cpython",
    "platform_python_implementation": "CPython",
    "sys_platform": "linux",
    "platform_system": "Linux",
    "platform_machine": "x86_64",
    "os_name": "posix",
    "extra": "",
}
_REQ_LINE = re.compile(r"^(\S+)==(\S+) --hash=sha256:([0-9a-f]{64})\s+# (\S+)$")


def say(message: str) -> None:
    print(f"sandbox-image: {message}", file=sys.stderr, flush=True)


# -------------------------------------------------------------------------------- inputs


def build_inputs() -> dict[str, bytes]:
    """Every file of the build context but the wheels, by its path in the context."""
    files = {
        "Dockerfile": (SANDBOX_DIR / "Dockerfile").read_bytes(),
        "requirements.txt": REQUIREMENTS.read_bytes(),
        "lib/sandbox/__init__.py": _STUB.encode(),
    }
    files.update(_package_files(SANDBOX_DIR / "harness", "lib/sandbox/harness"))
    for name in PROJECT_PACKAGES:
        files.update(_package_files(_package_dir(name), f"lib/{name}"))
    return files


def _package_dir(name: str) -> Path:
    import importlib.util

    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        raise SandboxUnavailable(f"package {name!r} is not importable; it goes into the image")
    return Path(next(iter(spec.submodule_search_locations))).resolve()


def _package_files(root: Path, prefix: str) -> dict[str, bytes]:
    out = {}
    for path in sorted(root.rglob("*")):
        rel = path.relative_to(root)
        skip = any(p == "__pycache__" or p.startswith(".") for p in rel.parts)
        if path.is_file() and not skip and path.suffix not in (".pyc", ".pyo"):
            out[f"{prefix}/{rel.as_posix()}"] = path.read_bytes()
    return out


def image_hash(inputs: dict[str, bytes] | None = None) -> str:
    """sha256 over the build inputs (paths and contents, in a fixed order)."""
    inputs = build_inputs() if inputs is None else inputs
    h = hashlib.sha256()
    for rel in sorted(inputs):
        data = inputs[rel]
        h.update(f"{rel}\0{len(data)}\0".encode())
        h.update(data)
    return h.hexdigest()


def image_tag() -> str:
    """The image tag for the current repository state, e.g. ``rivet-sandbox:3f2a9c0b1d4e``."""
    return f"{IMAGE_REPO}:{image_hash()[:12]}"


# -------------------------------------------------------------------------------- lock


def lock_requirements(lock_path: Path = REPO / "uv.lock") -> str:
    """requirements.txt for the image: the closure of ROOT_PACKAGES in uv.lock, one wheel each."""
    from packaging.markers import Marker
    from packaging.tags import compatible_tags, cpython_tags
    from packaging.utils import canonicalize_name, parse_wheel_filename

    lock = tomllib.loads(lock_path.read_text())
    by_name: dict[str, list[dict[str, Any]]] = {}
    for pkg in lock["package"]:
        by_name.setdefault(pkg["name"], []).append(pkg)
    project = [p for p in lock["package"] if p.get("source", {}).get("editable") == "."]
    if len(project) != 1:
        raise ImageBuildError("uv.lock has no (or several) editable project entries")

    def follow(deps: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
        out = []
        for dep in deps:
            if "marker" in dep and not Marker(dep["marker"]).evaluate(_MARKER_ENV):
                continue
            cands = [
                p for p in by_name[dep["name"]] if dep.get("version", p["version"]) == p["version"]
            ]
            if len(cands) != 1:
                raise ImageBuildError(f"uv.lock: cannot pick one version of {dep['name']!r}")
            out.append(cands[0])
        return out

    roots = [d for d in project[0]["dependencies"] if d["name"] in ROOT_PACKAGES]
    missing = set(ROOT_PACKAGES) - {d["name"] for d in roots}
    if missing:
        raise ImageBuildError(f"uv.lock: the project does not depend on {sorted(missing)}")
    chosen: dict[str, dict[str, Any]] = {}
    stack = follow(roots)
    while stack:
        pkg = stack.pop()
        if pkg["name"] in chosen:
            continue
        chosen[pkg["name"]] = pkg
        stack += follow(pkg.get("dependencies", []))

    platforms = [f"manylinux_2_{m}_x86_64" for m in range(36, 4, -1)]
    platforms += [
        "manylinux2014_x86_64",
        "manylinux2010_x86_64",
        "manylinux1_x86_64",
        "linux_x86_64",
    ]
    tags = list(cpython_tags((3, 11), ["cp311", "abi3", "none"], platforms))
    tags += list(compatible_tags((3, 11), "cp311", platforms))
    rank = {t: i for i, t in enumerate(tags)}
    lines = [
        "# The sandbox image's Python packages: the closure of sandbox.image.ROOT_PACKAGES in",
        "# uv.lock, one wheel each for CPython 3.11 on manylinux x86_64, with the wheel's URL.",
        "# Generated by `python -m sandbox.image lock`; a test checks it matches uv.lock.",
    ]
    for name in sorted(chosen):
        pkg = chosen[name]
        best = None
        for wheel in pkg.get("wheels", []):
            filename = wheel["url"].rsplit("/", 1)[1]
            wname, _, _, wtags = parse_wheel_filename(filename)
            score = min((rank[t] for t in wtags if t in rank), default=None)
            if (
                score is not None
                and canonicalize_name(wname) == name
                and (best is None or score < best[0])
            ):
                best = (score, wheel)
        if best is None:
            raise ImageBuildError(f"uv.lock has no CPython 3.11 manylinux x86_64 wheel of {name}")
        wheel = best[1]
        digest = wheel["hash"].removeprefix("sha256:")
        lines.append(f"{name}=={pkg['version']} --hash=sha256:{digest}  # {wheel['url']}")
    return "\n".join(lines) + "\n"


def read_requirements(path: Path = REQUIREMENTS) -> list[tuple[str, str, str, str]]:
    """(name, version, sha256, url) per pinned wheel."""
    out = []
    for line in path.read_text().splitlines():
        if not line or line.startswith("#"):
            continue
        m = _REQ_LINE.match(line)
        if not m:
            raise ImageBuildError(f"{path}: unexpected line {line!r}")
        out.append((m[1], m[2], m[3], m[4]))
    return out


# -------------------------------------------------------------------------------- wheels


def fetch_wheels(dest: Path = CACHE / "wheels") -> list[Path]:
    """The pinned wheels in the host wheelhouse, downloading (and checking) missing ones."""
    dest.mkdir(parents=True, exist_ok=True)
    reqs = read_requirements()
    todo = [r for r in reqs if not _has_wheel(dest, r)]
    if todo:
        say(f"downloading {len(todo)} of {len(reqs)} wheels into {dest}")
        t0 = time.monotonic()
        with concurrent.futures.ThreadPoolExecutor(4) as pool:
            for f in [pool.submit(_download, dest, r) for r in todo]:
                f.result()
        say(f"downloaded in {time.monotonic() - t0:.0f} s")
    return [dest / _wheel_name(r) for r in reqs]


def _wheel_name(req: tuple[str, str, str, str]) -> str:
    return urllib.parse.unquote(req[3].rsplit("/", 1)[1])


def _has_wheel(dest: Path, req: tuple[str, str, str, str]) -> bool:
    path = dest / _wheel_name(req)
    ok_marker = path.with_name(path.name + ".sha256")
    if path.is_file() and ok_marker.is_file() and ok_marker.read_text().strip() == req[2]:
        return True
    return path.is_file() and _sha256(path) == req[2] and not ok_marker.write_text(req[2])


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _download(dest: Path, req: tuple[str, str, str, str]) -> None:
    name, version, digest, url = req
    cafile = next(
        (
            p
            for p in (
                os.environ.get("SSL_CERT_FILE"),
                os.environ.get("PIP_CERT"),
                "/etc/ssl/certs/ca-certificates.crt",
            )
            if p and os.path.isfile(p)
        ),
        None,
    )
    context = ssl.create_default_context(cafile=cafile)
    path = dest / _wheel_name(req)
    part = path.with_name(path.name + ".part")
    h = hashlib.sha256()
    try:
        with urllib.request.urlopen(url, context=context, timeout=120) as r, open(part, "wb") as f:
            for chunk in iter(lambda: r.read(1 << 20), b""):
                h.update(chunk)
                f.write(chunk)
    except OSError as e:
        raise ImageBuildError(
            f"cannot download {name}=={version} from {url}: {e}. Put {path.name} into {dest} "
            "by hand on a machine without PyPI access."
        ) from None
    if h.hexdigest() != digest:
        part.unlink()
        raise ImageBuildError(
            f"{path.name}: sha256 {h.hexdigest()} does not match uv.lock's {digest}"
        )
    part.rename(path)
    path.with_name(path.name + ".sha256").write_text(digest)


# -------------------------------------------------------------------------------- docker


def docker_client(timeout: int = 600) -> Any:
    """A client for the local Docker engine; raises `SandboxUnavailable` with the fix."""
    import docker

    try:
        client = docker.from_env(timeout=timeout)
        try:
            client.ping()
        except Exception:
            client.close()
            raise
        return client
    except Exception as e:
        problem = f"{type(e).__name__}: {str(e)[:200]}"
    # The SDK leaks the socket of a failed connect; finalize it here, quietly, not at random.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        gc.collect()
    raise SandboxUnavailable(
        f"the Docker engine is not reachable ({problem}). Start it with `make system` (or "
        "`sudo dockerd &`), then `make sandbox-image`. The local backend (--sandbox local) "
        "runs without any isolation and is never chosen for you."
    )


def has_image(client: Any, ref: str) -> bool:
    import docker

    try:
        client.images.get(ref)
        return True
    except docker.errors.ImageNotFound:
        return False


def resolve_base(client: Any, requested: str | None = None) -> str:
    """The base to build on: asked for, else the public slim image, else the offline base."""
    requested = requested or os.environ.get("RIVET_SANDBOX_BASE")
    if requested:
        if requested == OFFLINE_BASE and not has_image(client, requested):
            build_base()
        elif not has_image(client, requested):
            say(f"pulling the requested base {requested}")
            client.images.pull(requested)
        return requested
    if has_image(client, ONLINE_BASE):
        say(f"base: {ONLINE_BASE} (present locally)")
        return ONLINE_BASE
    try:
        say(f"trying to pull {ONLINE_BASE}")
        repo, tag = ONLINE_BASE.split(":")
        client.images.pull(repo, tag=tag)
        say(f"base: {ONLINE_BASE} (pulled)")
        return ONLINE_BASE
    except Exception as e:
        say(
            f"cannot pull {ONLINE_BASE} ({str(e).splitlines()[0][:160]}); using the offline base {OFFLINE_BASE}"
        )
    if not has_image(client, OFFLINE_BASE):
        build_base()
    else:
        say(f"base: {OFFLINE_BASE} (present locally)")
    return OFFLINE_BASE


def build_base() -> None:
    """`make sandbox-base`: debootstrap + docker import (needs root and the Debian mirror)."""
    say(f"{OFFLINE_BASE} is missing: building it with sandbox/build_base.sh (debootstrap)")
    result = subprocess.run(["bash", str(SANDBOX_DIR / "build_base.sh")], check=False)
    if result.returncode != 0:
        raise ImageBuildError(f"sandbox/build_base.sh failed (exit {result.returncode}); see above")


def stage_context(inputs: dict[str, bytes], wheels: list[Path]) -> Path:
    """The build context under .cache/sandbox/context; wheels are hard links when possible."""
    ctx = CACHE / f"context-{os.getpid()}"
    shutil.rmtree(ctx, ignore_errors=True)
    (ctx / "wheels").mkdir(parents=True)
    for rel, data in inputs.items():
        path = ctx / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    for wheel in wheels:
        try:
            os.link(wheel, ctx / "wheels" / wheel.name)
        except OSError:
            shutil.copy2(wheel, ctx / "wheels" / wheel.name)
    return ctx


def ensure_image(*, base: str | None = None, rebuild: bool = False, quiet: bool = False) -> str:
    """Build the sandbox image unless its tag exists; returns the tag."""
    client = docker_client()
    try:
        inputs = build_inputs()
        digest = image_hash(inputs)
        tag = f"{IMAGE_REPO}:{digest[:12]}"
        if has_image(client, tag) and not rebuild:
            if not quiet:
                say(f"{tag} is up to date")
            return tag
        CACHE.mkdir(parents=True, exist_ok=True)
        with open(CACHE / "build.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # one build at a time (parallel test workers)
            if has_image(client, tag) and not rebuild:
                say(f"{tag} was built meanwhile")
                return tag
            return _build(client, tag, digest, inputs, base, quiet)
    finally:
        client.close()


def _build(
    client: Any, tag: str, digest: str, inputs: dict[str, bytes], base: str | None, quiet: bool
) -> str:
    say(f"building {tag} (inputs changed or image missing)")
    t0 = time.monotonic()
    chosen = resolve_base(client, base)
    ctx = stage_context(inputs, fetch_wheels())
    log: list[str] = []
    try:
        for chunk in client.api.build(
            path=str(ctx),
            tag=tag,
            buildargs={"BASE": chosen},
            labels={LABEL: "1", f"{LABEL}.hash": digest, f"{LABEL}.base": chosen},
            rm=True,
            forcerm=True,
            pull=False,
            decode=True,
        ):
            if "error" in chunk:
                raise ImageBuildError(
                    f"docker build failed: {chunk['error']}\n" + "".join(log[-30:])
                )
            line = chunk.get("stream", "")
            if line:
                log.append(line)
                if not quiet and line.strip():
                    print(f"  {line.rstrip()}", file=sys.stderr, flush=True)
    finally:
        shutil.rmtree(ctx, ignore_errors=True)
    say(f"built {tag} on {chosen} in {time.monotonic() - t0:.0f} s")
    return tag


def prune_images() -> list[str]:
    """Remove `rivet-sandbox` tags other than the current one; the tags removed."""
    client = docker_client()
    current = image_tag()
    removed = []
    for img in client.images.list(name=IMAGE_REPO):
        for ref in img.tags:
            if ref.startswith(f"{IMAGE_REPO}:") and ref != current:
                try:
                    client.images.remove(ref)
                    removed.append(ref)
                except Exception as e:  # in use by a running container, say
                    say(f"kept {ref}: {str(e)[:120]}")
    client.close()
    return removed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m sandbox.image", description=__doc__.splitlines()[0]
    )
    sub = parser.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("build", help="build the image if its tag is missing")
    b.add_argument("--base", help=f"base image (default: {ONLINE_BASE}, else {OFFLINE_BASE})")
    b.add_argument("--rebuild", action="store_true", help="build even if the tag exists")
    sub.add_parser("tag", help="print the image tag for this repository state")
    sub.add_parser("prune", help="remove sandbox image tags other than the current one")
    lk = sub.add_parser("lock", help="regenerate sandbox/requirements.txt from uv.lock")
    lk.add_argument("--check", action="store_true", help="only check it is up to date")
    args = parser.parse_args(argv)
    try:
        if args.cmd == "build":
            print(ensure_image(base=args.base, rebuild=args.rebuild))
        elif args.cmd == "tag":
            print(image_tag())
        elif args.cmd == "prune":
            removed = prune_images()
            say(f"removed {len(removed)} old tags: {', '.join(removed) or '-'}")
        else:
            text = lock_requirements()
            if args.check:
                if REQUIREMENTS.read_text() != text:
                    say("sandbox/requirements.txt is stale: run `python -m sandbox.image lock`")
                    return 1
            else:
                REQUIREMENTS.write_text(text)
                say(f"wrote {REQUIREMENTS} ({len(read_requirements())} wheels)")
    except (ImageBuildError, SandboxUnavailable) as e:
        say(f"error: {e}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
