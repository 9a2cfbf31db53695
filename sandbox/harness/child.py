"""The forked child: load a program's modules from source, then answer calls until told to stop.

Design rule: the child answers, the parent judges. The child writes one frame to its result pipe
when the program has loaded (ready / raised) and one frame per call request it reads from its
request pipe (returned / raised / unencodable); everything else it prints goes to the captured
stdout/stderr and is never parsed. Draft code runs in this same process, so it can write any
bytes it likes to the result pipe: whatever comes back is only ever taken as the draft's own
answer to the call in progress, and the parent alone measures time, watches the exit status and
the memory, and refuses anything out of turn.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util as ctypes_util
import fcntl
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
from .lockdown import find_library, make_undumpable
from .lockdown import install as install_filter

RESULT_FD = 3
REQUEST_FD = 4
_PR_SET_DUMPABLE = 4
MAX_MESSAGE = 4000  # [chars]
MAX_TRACEBACK = 8000  # [chars]
MAX_PROGRAM_FILE = 1 << 20  # [bytes] program.json
MAX_SOURCE = 16 << 20  # [bytes] one module's source
MAX_CONSTANTS = 256 << 20  # [bytes] constants, as the host caps them
_HARNESS_DIR = str(Path(__file__).resolve().parent)


def serve(
    *,
    program_dir: str,
    tmp_dir: str,
    result_fd: int,
    request_fd: int,
    out_fd: int,
    err_fd: int,
    memory_mb: int,
    output_limit: int,
    request_limit: int,
    lockdown: bool = False,
    template_pid: int = 0,
) -> NoReturn:
    """Set the child up, load the program, answer calls until the request pipe closes.

    With `lockdown` (inside the container) the process ends its setup non-dumpable under its
    own seccomp filter (`lockdown`), protecting the template `template_pid` and PID 1.
    """
    try:
        _isolate(result_fd, request_fd, out_fd, err_fd, memory_mb, lockdown, template_pid)
        os.chdir(tmp_dir)
        os.environ["TMPDIR"] = os.environ["HOME"] = tmp_dir
        tempfile.tempdir = None
        program = _Program.load(program_dir)
        frame = wire.pack_frame({"status": "ready"})
    except BaseException as e:  # the harness or the program's import failed
        _write(wire.pack_frame({"status": "raised", **_describe(e, _draft_files(program_dir))}))
        os._exit(0)
    _write(frame)
    reader = wire.FrameReader(request_limit)
    while True:
        request = _next_request(reader)
        if request is None:
            os._exit(0)
        _write(program.answer(*request, output_limit=output_limit, input_limit=request_limit))


def _write(frame: bytes) -> None:
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(BaseException):
            stream.flush()
    view = memoryview(frame)
    while view:
        view = view[os.write(RESULT_FD, view) :]


def _next_request(reader: wire.FrameReader) -> tuple[dict[str, Any], list[bytes]] | None:
    while True:
        for frame in reader.frames():
            return frame
        data = os.read(REQUEST_FD, 1 << 20)
        if not data:
            return None
        reader.feed(data)


def _isolate(
    result_fd: int,
    request_fd: int,
    out_fd: int,
    err_fd: int,
    memory_mb: int,
    lockdown: bool = False,
    template_pid: int = 0,
) -> None:
    """Own session, only the descriptors it needs, default signals, a memory limit; with
    `lockdown`, non-dumpable under the session filter."""
    # The harness is non-dumpable (so jobs cannot reach into it) and a fork inherits that;
    # the process is dumpable for as long as it needs to write its own /proc files.
    ctypes.CDLL(None).prctl(_PR_SET_DUMPABLE, 1, 0, 0, 0)
    os.setsid()
    # Every end moves above the fixed numbers first, so that no dup2 below clobbers another.
    high = [fcntl.fcntl(fd, fcntl.F_DUPFD, 64) for fd in (out_fd, err_fd, result_fd, request_fd)]
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    for fd, target in zip(high, (1, 2, RESULT_FD, REQUEST_FD), strict=True):
        os.dup2(fd, target)
    os.closerange(REQUEST_FD + 1, resource.getrlimit(resource.RLIMIT_NOFILE)[0])
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGQUIT, signal.SIGHUP, signal.SIGCHLD):
        signal.signal(sig, signal.SIG_DFL)
    try:  # the kernel's OOM killer takes the program, not the harness
        with open("/proc/self/oom_score_adj", "w") as f:
            f.write("1000")
    except OSError:
        if lockdown:  # the harness's safety rests on it
            raise
    # RLIMIT_DATA counts what the program allocates (heap, anonymous maps), not the address
    # space of the shared libraries the harness already mapped.
    data = _status_kib("VmData") * 1024 + memory_mb * (1 << 20)
    resource.setrlimit(resource.RLIMIT_DATA, (data, data))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    if lockdown:
        # Its /proc files (oom_score_adj among them) become root's, and the filter keeps it
        # so: no prctl(PR_SET_DUMPABLE, 1), no exec. Then nothing it starts can lower its OOM
        # preference below the harness's, or signal the template or PID 1.
        make_undumpable()
        install_filter(template_pid)
        ctypes_util.find_library = find_library  # the standard one runs programs


def _status_kib(key: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return 0


class _Program:
    """The loaded modules and the constants calls may refer to."""

    def __init__(
        self, root: Path, modules: dict[str, Any], constants: dict[str, Any], files: set[str]
    ):
        self.root = root
        self.modules = modules
        self.constants = constants
        self.files = files

    @staticmethod
    def load(program_dir: str) -> _Program:
        root = Path(program_dir)
        spec = json.loads(_read(root / "program.json", MAX_PROGRAM_FILE))
        sources = {
            name: _read(root / file, MAX_SOURCE).decode() for name, file in spec["sources"].items()
        }
        constants: dict[str, Any] = {}
        if spec.get("constants"):
            text = _read(root / spec["constants"]["json"], MAX_CONSTANTS)
            npz = spec["constants"].get("npz")
            blob = _read(root / npz, MAX_CONSTANTS) if npz else b""
            raw = wire.decode_value(text, blob, max_bytes=2 * MAX_CONSTANTS)
            for name, kind in spec["constants"]["kinds"].items():
                constants[name] = _materialize(kind, raw[name])
        modules = _load_modules(sources)
        return _Program(root, modules, constants, {f"{name}.py" for name in sources})

    def answer(
        self,
        header: Mapping[str, Any],
        sections: list[bytes],
        *,
        output_limit: int,
        input_limit: int,
    ) -> bytes:
        """The frame answering one request: ``op`` "call" (the default) calls a function,
        "attribute" returns a module attribute's value, "signature" describes a function.
        A call's arrays come in its second section, or in the file ``args/<arrays_file>`` of
        the program's folder (named by the harness, written by the host)."""
        try:
            op = header.get("op", "call")
            if op == "attribute":
                value = self._attribute(header)
            elif op == "signature":
                value = self._signature(header)
            else:
                fn = self._function(header)
                if len(sections) != 2:
                    raise ValueError("a call request carries its arguments in two sections")
                blob = sections[1]
                if header.get("arrays_file"):
                    blob = _read(self.root / "args" / str(header["arrays_file"]), input_limit)
                args = wire.decode_value(sections[0], blob, max_bytes=1 << 40)
                value = fn(*self._resolve(args["args"]), **self._resolve(args["kwargs"]))
            text, blob = wire.encode_value(value, max_bytes=output_limit)
        except wire.BadValue as e:
            problem = f"{e.path.replace('$', 'output', 1)}: {e.problem}"
            return wire.pack_frame({"status": "unencodable", "problem": problem[:MAX_MESSAGE]})
        except BaseException as e:
            return wire.pack_frame({"status": "raised", **_describe(e, self.files)})
        return wire.pack_frame({"status": "returned"}, [text, blob])

    def _module(self, header: Mapping[str, Any]) -> Any:
        module = self.modules.get(str(header.get("module")))
        if module is None:
            raise ImportError(f"the program has no module {header.get('module')!r}")
        return module

    def _attribute(self, header: Mapping[str, Any]) -> Any:
        name = str(header.get("function"))
        module = self._module(header)
        if not hasattr(module, name):
            raise AttributeError(f"module {module.__name__!r} has no attribute {name!r}")
        return getattr(module, name)

    def _signature(self, header: Mapping[str, Any]) -> dict[str, Any]:
        """{"callable", "params": [{"name", "kind", "default"}] or None, "functions"}."""
        import inspect

        module = self._module(header)
        fn = getattr(module, str(header.get("function")), None)
        params = None
        if callable(fn):
            try:
                params = [
                    {"name": p.name, "kind": p.kind.name, "default": p.default is not p.empty}
                    for p in inspect.signature(fn).parameters.values()
                ]
            except (TypeError, ValueError):  # a builtin: nothing to compare
                params = None
        functions = sorted(
            n for n, v in vars(module).items() if inspect.isfunction(v) and not n.startswith("_")
        )
        return {"callable": callable(fn), "params": params, "functions": functions}

    def _function(self, header: Mapping[str, Any]) -> Any:
        module = self.modules.get(str(header.get("module")))
        if module is None:
            raise ImportError(f"the program has no module {header.get('module')!r}")
        name = str(header.get("function"))
        fn = getattr(module, name, None)
        if not callable(fn):
            raise AttributeError(f"module {module.__name__!r} defines no function {name!r}")
        return fn

    def _resolve(self, value: Any) -> Any:
        """Arguments with ``{"__const__": name}`` replaced by a fresh copy of that constant."""
        if isinstance(value, dict):
            if set(value) == {wire.CONST_KEY}:
                name = value[wire.CONST_KEY]
                if name not in self.constants:
                    raise KeyError(f"the program has no constant {name!r}")
                return _fresh(self.constants[name])
            return {k: self._resolve(v) for k, v in value.items()}
        if isinstance(value, list):
            return [self._resolve(v) for v in value]
        return value


def _materialize(kind: str, value: Any) -> Any:
    """A constant of a known kind from its wire form."""
    if kind == "value":
        return value
    if kind == "meshes":  # {key: {"vertices" (n, 3), "faces" (m, 3)}} → {key: trimesh.Trimesh}
        import trimesh

        return {
            key: trimesh.Trimesh(vertices=m["vertices"], faces=m["faces"], process=False)
            for key, m in value.items()
        }
    raise ValueError(f"unknown constant kind {kind!r}")


def _fresh(value: Any) -> Any:
    """A copy a program may modify without changing what the next call gets."""
    if isinstance(value, dict):
        return {k: _fresh(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_fresh(v) for v in value]
    copy = getattr(value, "copy", None)
    return copy() if callable(copy) else value


def _read(path: Path, limit: int) -> bytes:
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size  # not read(limit): that allocates `limit` bytes
        if size > limit:
            raise ValueError(f"{path.name} is over {limit} bytes")
        return f.read(size)


def _draft_files(program_dir: str) -> set[str]:
    try:
        spec = json.loads(_read(Path(program_dir) / "program.json", MAX_PROGRAM_FILE))
        return {f"{name}.py" for name in spec["sources"]}
    except BaseException:
        return set()


def _load_modules(sources: Mapping[str, str]) -> dict[str, Any]:
    """Import the program's modules from source, in order; they may import each other by name."""
    clash = sorted(name for name in sources if name in sys.modules)
    if clash:
        raise ImportError(
            f"module names {clash} are taken in the sandbox; rename the program's modules"
        )
    for name, source in sources.items():
        lines = source.splitlines(keepends=True)
        linecache.cache[f"{name}.py"] = (len(source), None, lines, f"{name}.py")
    sys.meta_path.insert(0, _SourceFinder(sources))
    return {name: importlib.import_module(name) for name in sources}


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


def _describe(e: BaseException, draft_files: set[str]) -> dict[str, Any]:
    """The exception as type, message and a traceback trimmed to the program's frames."""
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
        if not keep:  # not raised through the program: where it was raised, harness excluded
            keep = [f for f in frames if not f.filename.startswith((_HARNESS_DIR, "<frozen"))][-3:]
        head = f"Traceback ({len(keep)} of {len(frames)} frames: the program's):\n"
        body = "".join(traceback.StackSummary.from_list(keep).format())
        text = head + body + "".join(traceback.format_exception_only(kind, e))
    except BaseException:
        text = ""
    if len(text) > MAX_TRACEBACK:
        text = "…" + text[-MAX_TRACEBACK:]
    return {
        "oom": isinstance(e, MemoryError),
        "exception": {
            "type": wire.clean_text(name[:200]),
            "message": wire.clean_text(message[:MAX_MESSAGE]),
            "traceback": wire.clean_text(text),
        },
    }
