"""The forked child: load a job's draft modules from source, run it, report on a private pipe.

Design rule: the child reports, the parent judges. The child writes exactly one frame to the
result pipe (returned / raised / unencodable) and exits; everything else it prints goes to the
captured stdout/stderr and is never parsed. Draft code runs in this same process, so it can
forge this frame; forging only ever yields the draft's own output, which the host validates
like any other, and the exit status and timing are observed by the parent, not reported.
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib
import importlib.abc
import importlib.util
import json
import linecache
import os
import resource
import signal
import sys
import tempfile
import traceback
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NoReturn

from . import wire
from .context import EntryContext

RESULT_FD = 3
_PR_SET_DUMPABLE = 4
MAX_MESSAGE = 4000  # [chars]
MAX_TRACEBACK = 8000  # [chars]
MAX_JOB_FILE = 1 << 20  # [bytes] job.json
MAX_INPUT = 256 << 20  # [bytes] inputs, as the host caps them
_HARNESS_DIR = str(Path(__file__).resolve().parent)


def run(
    *,
    job_dir: str,
    tmp_dir: str,
    result_fd: int,
    out_fd: int,
    err_fd: int,
    memory_mb: int,
    output_limit: int,
) -> NoReturn:
    """Set the child up, run the job, write one frame to the result pipe and exit."""
    try:
        _isolate(result_fd, out_fd, err_fd, memory_mb)
        os.chdir(tmp_dir)
        os.environ["TMPDIR"] = os.environ["HOME"] = tmp_dir
        tempfile.tempdir = None
        frame = _run_job(job_dir, tmp_dir, output_limit)
    except BaseException as e:  # the harness itself failed before the job started
        frame = wire.pack_frame({"status": "raised", **_describe(e, set())})
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(BaseException):
            stream.flush()
    try:
        view = memoryview(frame)
        while view:
            view = view[os.write(RESULT_FD, view) :]
    finally:
        os._exit(0)


def _isolate(result_fd: int, out_fd: int, err_fd: int, memory_mb: int) -> None:
    """Own session, only the four descriptors it needs, default signals, a memory limit."""
    # The harness is non-dumpable (so jobs cannot reach into it) and a fork inherits that;
    # the job itself may be dumpable, which gives it back its own /proc/self files.
    ctypes.CDLL(None).prctl(_PR_SET_DUMPABLE, 1, 0, 0, 0)
    os.setsid()
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.dup2(out_fd, 1)
    os.dup2(err_fd, 2)
    os.dup2(result_fd, RESULT_FD)
    os.closerange(RESULT_FD + 1, resource.getrlimit(resource.RLIMIT_NOFILE)[0])
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGQUIT, signal.SIGHUP, signal.SIGCHLD):
        signal.signal(sig, signal.SIG_DFL)
    try:  # the kernel's OOM killer takes the job, not the harness
        with open("/proc/self/oom_score_adj", "w") as f:
            f.write("1000")
    except OSError:
        pass
    # RLIMIT_DATA counts what the job allocates (heap, anonymous maps), not the address space
    # of the shared libraries the harness already mapped.
    data = _status_kib("VmData") * 1024 + memory_mb * (1 << 20)
    resource.setrlimit(resource.RLIMIT_DATA, (data, data))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def _status_kib(key: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return 0


def _run_job(job_dir: str, tmp_dir: str, output_limit: int) -> bytes:
    root = Path(job_dir)
    spec = json.loads(_read(root / "job.json", MAX_JOB_FILE))
    sources = {
        name: _read(root / file, MAX_JOB_FILE * 16).decode()
        for name, file in spec["sources"].items()
    }
    files = {f"{name}.py" for name in sources}
    try:
        entry = _resolve_entry(spec["entry"])
        modules = _load_modules(spec["module"], sources)
        inputs = _load_inputs(root, spec.get("inputs"), MAX_INPUT)
        if entry is None:
            fn = getattr(modules[spec["module"]], spec["function"], None)
            if not callable(fn):
                raise AttributeError(f"the draft defines no function {spec['function']!r}")
            value = fn(**inputs)
        else:
            ctx = EntryContext(
                draft=modules[spec["module"]],
                modules=modules,
                function=spec["function"],
                inputs=inputs,
                tmp_dir=tmp_dir,
            )
            value = entry(ctx)
        text, blob = wire.encode_value(value, max_bytes=output_limit)
    except wire.BadValue as e:
        problem = f"{e.path.replace('$', 'output', 1)}: {e.problem}"
        return wire.pack_frame({"status": "unencodable", "problem": problem[:MAX_MESSAGE]})
    except BaseException as e:
        return wire.pack_frame({"status": "raised", **_describe(e, files)})
    return wire.pack_frame({"status": "returned"}, [text, blob])


def _read(path: Path, limit: int) -> bytes:
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size  # not read(limit): that allocates `limit` bytes
        if size > limit:
            raise ValueError(f"{path.name} is over {limit} bytes")
        return f.read(size)


def _resolve_entry(entry: str) -> Any:
    """None for "call"; else the function named by "pkg.mod:fn", imported from the image."""
    if entry == "call":
        return None
    module_name, _, attr = entry.partition(":")
    fn = getattr(importlib.import_module(module_name), attr, None)
    if not callable(fn):
        raise AttributeError(f"entry point {entry!r} is not a function")
    return fn


def _load_modules(main: str, sources: Mapping[str, str]) -> dict[str, Any]:
    """Import the job's modules from source; they may import each other by name."""
    clash = sorted(name for name in sources if name in sys.modules)
    if clash:
        raise ImportError(
            f"module names {clash} are taken in the sandbox; rename the draft modules"
        )
    for name, source in sources.items():
        lines = source.splitlines(keepends=True)
        linecache.cache[f"{name}.py"] = (len(source), None, lines, f"{name}.py")
    sys.meta_path.insert(0, _SourceFinder(sources))
    modules = {main: importlib.import_module(main)}
    for name in sources:
        modules[name] = importlib.import_module(name)
    return modules


class _SourceFinder(importlib.abc.MetaPathFinder):
    def __init__(self, sources: Mapping[str, str]) -> None:
        self.sources = sources

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> Any:
        if fullname not in self.sources:
            return None
        loader = _SourceLoader(fullname, self.sources[fullname])
        return importlib.util.spec_from_loader(fullname, loader, origin=f"{fullname}.py")


class _SourceLoader(importlib.abc.Loader):
    def __init__(self, name: str, source: str) -> None:
        self.name, self.source = name, source

    def create_module(self, spec: Any) -> None:
        return None

    def exec_module(self, module: Any) -> None:
        module.__file__ = f"{self.name}.py"
        code = compile(self.source, module.__file__, "exec", dont_inherit=True)
        exec(code, module.__dict__)

    def get_source(self, name: str) -> str:
        return self.source


def _load_inputs(root: Path, files: Any, limit: int) -> dict[str, Any]:
    if not files:
        return {}
    text = _read(root / files["json"], limit)
    blob = _read(root / files["npz"], limit) if files.get("npz") else b""
    inputs = wire.decode_value(text, blob, max_bytes=2 * limit)
    if not isinstance(inputs, dict):
        raise TypeError("job inputs are not a mapping of argument names to values")
    return inputs


def _describe(e: BaseException, draft_files: set[str]) -> dict[str, Any]:
    """The exception as type, message and a traceback trimmed to the draft's frames."""
    kind = type(e)
    name = (
        kind.__qualname__
        if kind.__module__ == "builtins"
        else f"{kind.__module__}.{kind.__qualname__}"
    )
    try:
        message = str(e)
    except BaseException:
        message = "<unprintable exception>"
    try:
        frames = traceback.extract_tb(e.__traceback__)
        keep = [f for f in frames if f.filename in draft_files]
        if not keep:  # not raised through the draft: show where it was raised, harness excluded
            keep = [f for f in frames if not f.filename.startswith((_HARNESS_DIR, "<frozen"))][-3:]
        head = f"Traceback ({len(keep)} of {len(frames)} frames: the draft's):\n"
        body = "".join(traceback.StackSummary.from_list(keep).format())
        text = head + body + "".join(traceback.format_exception_only(kind, e))
    except BaseException:
        text = ""
    if len(text) > MAX_TRACEBACK:
        text = "…" + text[-MAX_TRACEBACK:]
    return {
        "oom": isinstance(e, MemoryError),
        "exception": {"type": name[:200], "message": message[:MAX_MESSAGE], "traceback": text},
    }
