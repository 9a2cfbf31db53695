"""Checks a draft cannot forge (issue 16, parts 1–2 and 4), through `rivet check` on the real
engine.

For each function, drafts whose function returns garbage (a dict dressed as a passing report)
try every route a draft has to change what the checks report — patching the check suite,
`contracts` and the harness's own answering code at import, patching builtins and `json`,
writing forged result frames (harness-, host- and report-shaped) on every descriptor it holds,
writing a frame then exiting, forking a process that answers later calls, hunting for the
judges' inputs, poisoning the container for the judge's later sessions — and `rivet check`
must exit 1 for each. Then a `perceive` that searches everything it can reach, run with
exactly the perceive checks' inputs after a session that received every scene's truth, must
find none of the true poses in any encoding; and hostile values sent back to the judge give
failed checks, never a traceback, a bare NaN or an escape sequence on the terminal.

The CLI runs in this process (`rivet.cli.main`) with its executor taken from one warm Docker
executor (the real engine; only the container start is shared), except where a test says
it opens its own.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest

import sandbox
from rivet.cli import main
from tests.sandbox.conftest import require_docker

from .conftest import CASES_SEED, PROGRAMS, program

pytestmark = pytest.mark.docker

SIGNATURES = {
    "render": "records, meshes, camera",
    "perceive": "observation, meshes, camera",
    "relate": "records, meshes",
    "plan": "start_state, goal_state, meshes",
}

# What every draft's module starts with: the forged "passing" value and the frames a forger
# would write (the harness's answer, the host's answer, a report, the CLI's own lines).
COMMON = '''
import json, os, sys, time, types
from sandbox.harness import wire
FORGED = {"passed": True, "status": "passed", "verdict": "ok", "first_failure": None,
          "checks": [{"name": "schema.output", "category": "schema", "status": "passed"}]}
def forged_frames():
    text, blob = wire.encode_value(FORGED, max_bytes=1 << 20)
    return [wire.pack_frame({"status": "ready"}),
            wire.pack_frame({"status": "returned"}, [text, blob]),
            wire.pack_frame({"kind": "answer", "verdict": "ok", "alive": True, "id": "s"},
                            [text, blob]),
            wire.pack_frame({"kind": "opened", "verdict": "ok"}),
            json.dumps(FORGED).encode() + b"\\n",
            b"ok   schema.output\\n**passed all 11 checks**\\n"]
def spray():
    """Every forged frame on every descriptor this process holds."""
    for name in os.listdir("/proc/self/fd"):
        for frame in forged_frames():
            try:
                os.write(int(name), frame)
            except OSError:
                pass
'''

ROUTES: dict[str, tuple[str, str]] = {  # name: (module-level code, function body)
    "patch_suite_modules": (
        """
class _Passing(types.ModuleType):
    def __getattr__(self, name):
        return lambda *a, **k: FORGED
for _name in ("checks", "checks.run", "checks.report", "checks.context", "checks.calls",
              "checks.inputs", "checks.images", "checks.suites", "checks.suites.render",
              "checks.suites.perceive", "checks.suites.relate", "checks.suites.plan",
              "checks.properties", "contracts.checks", "contracts.checks.suite", "domains",
              "sim", "artifacts"):
    sys.modules[_name] = _Passing(_name)
import contracts.validate, contracts.functions
contracts.validate.validate = lambda *a, **k: None
# the harness's own answering code, in this process: every answer says "passed"
from sandbox.harness import child
def _answer(self, header, sections, *, output_limit):
    text, blob = wire.encode_value(FORGED, max_bytes=output_limit)
    return wire.pack_frame({"status": "returned", "verdict": "ok", "passed": True}, [text, blob])
child._Program.answer = _answer
""",
        "return FORGED",
    ),
    "patch_builtins_and_json": (
        """
import builtins
json.dumps = lambda *a, **k: json.JSONEncoder().encode(FORGED)
json.loads = lambda *a, **k: FORGED
builtins.isinstance = lambda obj, kind: True
builtins.print = lambda *a, **k: None
""",
        "return FORGED",
    ),
    "spray_forged_frames": ("spray()", "spray()\n    return FORGED"),
    "frames_then_exit_at_import": ("spray()\nos._exit(0)", "return FORGED"),
    "frame_then_exit_in_a_call": (
        "",
        "text, blob = wire.encode_value(FORGED, max_bytes=1 << 20)\n"
        "    os.write(3, wire.pack_frame({'status': 'returned'}, [text, blob]) * 3)\n"
        "    os._exit(0)",
    ),
    "forked_answerer": (
        """
if os.fork() == 0:  # a process of its own that answers every later request with FORGED
    os.setsid()
    reader = wire.FrameReader(1 << 30)
    text, blob = wire.encode_value(FORGED, max_bytes=1 << 20)
    while True:
        data = os.read(4, 1 << 20)
        if not data:
            os._exit(0)
        reader.feed(data)
        for _ in reader.frames():
            os.write(3, wire.pack_frame({"status": "returned"}, [text, blob]))
""",
        "text, blob = wire.encode_value(FORGED, max_bytes=1 << 20)\n"
        "    os.write(3, wire.pack_frame({'status': 'returned'}, [text, blob]))\n"
        "    time.sleep(10 ** 6)  # the forked process answers from now on",
    ),
    "hunt_for_judge_inputs": (
        '''
def _hunt():
    """Whatever the judges hold: their modules, staged files, other processes, variables."""
    found = []
    for name in ("checks", "checks.inputs", "domains", "sim", "sim.observation", "artifacts"):
        try:
            __import__(name)
            found.append(("module", name))
        except Exception:
            pass
    for root in ("/in", "/tmp", "/dev/shm", "/run", "/var/tmp", "/home", "/root"):
        for folder, _, files in os.walk(root):
            for f in files:
                try:
                    with open(os.path.join(folder, f), "rb") as fh:
                        data = fh.read(1 << 20)
                except OSError:
                    continue
                if any(k in data for k in (b"truth", b"reference", b'"pose"', b"expected")):
                    found.append(("file", os.path.join(folder, f)))
                    try:
                        return json.loads(data)  # records, relations or a plan to hand back
                    except ValueError:
                        pass
    for pid in os.listdir("/proc"):
        for what in ("environ", "cmdline"):
            try:
                with open(f"/proc/{pid}/{what}", "rb") as fh:
                    if b"truth" in fh.read():
                        found.append(("proc", pid))
            except OSError:
                pass
    return FORGED if not found else {**FORGED, "found": [list(f) for f in found]}
''',
        "return _hunt()",
    ),
    "poison_later_sessions": (
        """
PLANT = "import os\\nos.environ['RIVET_POISON'] = '1'\\n"
if os.fork() == 0:  # outlive the session; plant modules for whatever runs next
    os.setsid()
    while True:
        for folder in ("/tmp", "/dev/shm", os.getcwd()):
            for name in ("render", "relate", "toolbox", "numpy", "colorsys", "sitecustomize"):
                try:
                    with open(os.path.join(folder, name + ".py"), "w") as fh:
                        fh.write(PLANT)
                except OSError:
                    pass
        spray()
        time.sleep(0.05)
""",
        "spray()\n    return FORGED",
    ),
}


def draft(function: str, route: str) -> str:
    prefix, body = ROUTES[route]
    return f"{COMMON}\n{prefix}\n\ndef {function}({SIGNATURES[function]}):\n    {body}\n"


class _Borrowed:
    """The warm executor, lent to one `rivet check` (which closes what it opens)."""

    def __init__(self, executor) -> None:
        self._executor = executor

    def __getattr__(self, name):
        return getattr(self._executor, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        pass

    def close(self) -> None:
        pass


@pytest.fixture(scope="module")
def docker():
    require_docker()
    from sandbox.docker_backend import DockerExecutor
    from sandbox.image import ensure_image

    with DockerExecutor(image=ensure_image(quiet=True)) as ex:  # the default 6 GiB
        ex.warm()
        yield ex


@pytest.fixture
def rivet_check(docker, monkeypatch, tmp_path):
    """rivet_check(function, source, deps=None, own=False, only=()) -> (exit code, report,
    output); `only`: `--only` these checks."""

    def run(
        function: str,
        source: str,
        deps: Path | None = PROGRAMS,
        own: bool = False,
        only: tuple[str, ...] = (),
    ):
        if not own:
            monkeypatch.setattr(sandbox, "open_executor", lambda *a, **k: _Borrowed(docker))
        path = tmp_path / f"{function}_draft.py"
        path.write_text(source, encoding="utf-8", errors="surrogatepass")
        argv = ["check", "cubes", function, str(path), "--json", "--out", str(tmp_path / "out")]
        argv += ["--seed", str(CASES_SEED)]  # the same cases every run
        if deps is not None:
            argv += ["--deps", str(deps)]
        for name in only:
            argv += ["--only", name]
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(argv)
        text = out.getvalue() + err.getvalue()
        assert "Traceback (most recent call last)" not in text, text[
            -3000:
        ]  # ours, not the draft's
        return code, _strict_json(out.getvalue()), text

    return run


def _strict_json(text: str):
    def refuse(name):
        raise ValueError(f"bare {name} in the report")

    return json.loads(text, parse_constant=refuse)


def _not_passing(report: dict) -> list[str]:
    return [c["name"] for c in report["checks"] if c["status"] != "passed"]


@pytest.mark.parametrize("function", list(SIGNATURES))
@pytest.mark.parametrize("route", list(ROUTES))
def test_forging_routes_are_rejected(rivet_check, docker, function, route):
    code, report, _ = rivet_check(function, draft(function, route))
    assert code == 1, f"{route}: rivet check {function} passed a draft that returns garbage"
    assert report["passed"] is False
    judged = {"interface.import", "interface.signature", "interface.runs", "schema.output"}
    assert judged & set(_not_passing(report)), _not_passing(report)
    assert docker.run(sandbox.Job(source="def f():\n    return 7\n", function="f")).output == 7


@pytest.mark.parametrize("function", ["relate", "render"])
def test_forging_through_the_cli_own_executor(rivet_check, function):
    """The same, with `rivet check` opening (and closing) its own Docker executor."""
    code, report, _ = rivet_check(function, draft(function, "patch_suite_modules"), own=True)
    assert code == 1 and report["passed"] is False


def test_the_same_path_passes_a_correct_draft(rivet_check):
    """The control: the reference `relate` passes through exactly this path."""
    code, report, text = rivet_check("relate", program("relate"))
    assert code == 0 and report["passed"] is True, text[-2000:]


# ---------------------------------------------------------------------------- ground truth


def _occurrences(T: np.ndarray, blob: bytes, text: str) -> list[str]:
    """How pose `T` (4×4) occurs in `blob`/`text`, in any encoding we can think of."""
    found = []
    for dtype in (np.float64, np.float32):
        M = np.asarray(T, dtype)
        needles = {
            "4x4 row-major": M.tobytes(),
            "3x4 row-major": M[:3].tobytes(),
            "4x4 column-major": M.T.tobytes(),
            "translation": np.ascontiguousarray(M[:3, 3]).tobytes(),
            "row 0": M[0].tobytes(),
            "row 1": M[1].tobytes(),
        }
        for what, needle in needles.items():
            if needle in blob:
                found.append(f"{np.dtype(dtype).name} {what}")
    x, y = float(T[0, 3]), float(T[1, 3])
    for p in (3, 4, 5, 6, 8, 10, 12, 15):
        pattern = re.escape(f"{x:.{p}f}") + r"[\s,;:\]\[\"'a-z_]{1,24}" + re.escape(f"{y:.{p}f}")
        if re.search(pattern, text):
            found.append(f"decimal x, y at {p} places")
    if re.search(re.escape(repr(x)) + r"[^0-9]{1,24}" + re.escape(repr(y)), text):
        found.append("repr / JSON x, y")
    return found


SEARCHED = 8  # observations the searcher is called on (a call after the first takes ~1 s)


def test_a_perceive_session_can_reach_no_ground_truth(docker):
    """A `perceive` that searches its whole file system, environment, /proc and its own
    memory, called with the perceive checks' inputs in a session set up as `checks.run` sets
    it up, right after a session of the same warm container received the true records of
    every one of those scenes (as a `relate` check does), finds none of them — and does find
    a control pose planted where it can be reached.

    The searcher is called on the first `SEARCHED` observations (the hiding cases, then
    generated and composed scenes from drawn and named cameras): its first call searches
    everything, later calls only what changes from call to call (its memory and arguments),
    by the same code path for every observation."""
    import checks.run
    import domains
    from checks.budget import DEFAULT
    from checks.calls import session_modules
    from checks.context import DomainSpec

    dom = domains.load("cubes")
    spec = DomainSpec.of(dom)
    # the cases the perceive routes above were checked on, drawn as `checks.run` draws them
    cases = checks.run.build_cases(dom, "perceive", DEFAULT, seed=CASES_SEED)
    observations = cases["observations"]
    truth = [np.asarray(r["pose"], float) for case in observations for r in case["truth"]]
    assert len(truth) >= 20

    relate = sandbox.Program(
        modules=session_modules("relate", program("relate"), {}), meshes=spec.meshes
    )
    with docker.open_session(relate) as session:  # the judge's other sessions saw the truth
        for case in observations:
            got = session.call("relate", "relate", case["truth"], sandbox.MESHES, timeout_s=30)
            assert got.ok, got

    # The control, to show the search finds what is there: a random pose the host stages in
    # the searcher's own /in folder (a program constant the checks never send).
    rng = np.random.default_rng(16)
    planted = np.eye(4)
    planted[:3, :3] = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    planted[:3, :3] *= np.sign(np.linalg.det(planted[:3, :3]))
    planted[:3, 3] = rng.uniform(-1, 1, 3)
    source = (Path(__file__).parent / "search_draft.py").read_text()
    searcher = sandbox.Program(
        modules=session_modules("perceive", source, {"render": program("render")}),
        meshes=spec.meshes,
        constants={"planted": planted},
    )
    dumps = []
    with docker.open_session(searcher, memory_mb=4096, load_timeout_s=60) as session:
        assert session.load.ok, session.load
        for case in observations[:SEARCHED]:
            got = session.call(
                "perceive",
                "perceive",
                case["observation"],
                sandbox.MESHES,
                case["camera"],
                timeout_s=180,
            )
            assert got.ok, got
            dumps.append(got.value)
    first = dumps[0]["stats"]
    print("search:", first)  # third-party files skipped for time are `truncated`
    # the places a run can write and the project's own are searched in full; the read-only
    # third-party trees for as long as the search's time lasts (on a loaded machine fewer)
    assert first["files"] > 10_000 or first["truncated"] > 0, first
    assert first["memory_bytes"] > 50 << 20, first
    assert first["blob_truncated"] == 0 and first["writable_files"] > 0, first
    assert any(name.startswith("/in/") for name, _, _ in dumps[0]["index"]), "/in was searched"
    assert any(name == "environment" for name, _, _ in dumps[0]["index"])

    blob = b"".join(
        bytes(d[k].tobytes()) for d in dumps for k in ("blob", "snippets", "candidates64")
    ) + b"".join(np.asarray(d["candidates32"], np.float32).tobytes() for d in dumps)
    text = blob.decode("latin-1")
    assert _occurrences(planted, blob, text), "the search missed the planted control pose"
    leaks = {}
    for k, T in enumerate(truth):
        found = _occurrences(T, blob, text)
        for d in dumps:
            for name in ("candidates64", "candidates32"):
                cand = np.asarray(d[name], float).reshape(-1, 3, 4)
                tol = 1e-9 if name == "candidates64" else 1e-6
                if len(cand) and np.any(np.all(np.abs(cand - T[:3]) < tol, axis=(1, 2))):
                    found.append(f"a rigid transform among its {name}")
        if found:
            leaks[k] = found
    assert not leaks, f"true poses reachable from the draft's session: {leaks}"


# --------------------------------------------------------------------------- hostile values


ESC = "\x1b]0;owned\x07\x1b[2J\x9b31m"


def _clean(text: str) -> bool:
    return not any(
        0xD800 <= ord(c) <= 0xDFFF or (ord(c) < 32 and c not in "\t\n") or 0x7F <= ord(c) <= 0x9F
        for c in text
    )


@pytest.mark.parametrize(
    ("function", "body"),
    [
        ("perceive", f"return [{{'id': {ESC + chr(0xD800)!r}, 'mesh': 'cube', 'pose': NAN_POSE}}]"),
        ("perceive", f"raise ValueError({ESC + ' contracts.checks failed ' + chr(0xDCFF)!r})"),
        (
            "render",
            "return {'rgb': np.zeros((0, 10**6, 3), np.uint8), 'depth': np.full((2, 2), np.nan),"
            " 'mask': np.zeros((10**5, 0), np.int64)}",
        ),
        ("relate", f"return {{'nodes': [{{'id': {ESC!r}}}], 'links': [], 'x': float('nan')}}"),
        (
            "plan",
            "return {'status': 'ok', 'steps': [{'object': 'red', 'target_pose': NAN_POSE}] * 3}",
        ),
    ],
    ids=[
        "escaped_ids_nan_poses",
        "escaped_exception",
        "zero_width_renders",
        "escaped_graph",
        "nan_plan",
    ],
)
def test_hostile_values_fail_checks_cleanly(rivet_check, function, body):
    source = (
        "import numpy as np\n"
        "NAN_POSE = [[1, 0, 0, float('nan')], [0, 1, 0, 0], [0, 0, 1, float('inf')], [0, 0, 0, 1]]\n"
        f"def {function}({SIGNATURES[function]}):\n    {body}\n"
    )
    code, report, text = rivet_check(function, source)
    assert code == 1 and report["passed"] is False
    assert _clean(text), [c for c in text if not _clean(c)][:10]
    from checks import report_markdown

    markdown = report_markdown(report)  # what the model would read
    assert _clean(markdown)


def test_wrong_shape_renders_reach_the_image_comparison_cleanly(rivet_check, tmp_path):
    """A frozen `render` whose images have the wrong shapes, re-rendering what a schema-valid
    `perceive` found: the image check fails, with no traceback."""
    deps = tmp_path / "deps"
    deps.mkdir()
    (deps / "render.py").write_text(
        "import numpy as np\n"
        "def render(records, meshes, camera):\n"
        "    return {'rgb': np.zeros((7, 5, 4), np.uint8), 'depth': np.zeros((3,), np.float32),\n"
        "            'mask': np.zeros((camera['width'], camera['height']), np.int32)}\n"
    )
    perceive = (
        "import numpy as np\n"
        "def perceive(observation, meshes, camera):\n"
        "    ids = ['red', 'green', 'blue', 'yellow', 'purple', 'cyan']\n"
        "    out = []\n"
        "    for k, i in enumerate(ids):\n"
        "        T = np.eye(4); T[:3, 3] = [0.4 + 0.06 * k, 0.0, 0.02]\n"
        "        out.append({'id': i, 'mesh': 'cube', 'pose': T})\n"
        "    return out\n"
    )
    code, report, _ = rivet_check("perceive", perceive, deps=deps)
    assert code == 1
    image = next(c for c in report["checks"] if c["name"] == "image.perceive_rerender")
    assert image["status"] == "failed" and "shape" in image["message"], image


DEGENERATE = {  # function: (a degenerate but well-formed output, the check that needs more)
    "perceive": ("return []", "property.accuracy"),
    "plan": ("return {'status': 'ok', 'steps': []}", "property.reaches_goal"),
    "render": (
        "h, w = camera['height'], camera['width']\n"
        "    return {'rgb': np.zeros((h, w, 3), np.uint8), 'depth': np.zeros((h, w), np.float32),"
        " 'mask': np.full((h, w), -1, np.int32)}",
        "image.render_vs_simulator",
    ),
    "relate": (
        "return {'directed': True, 'multigraph': False, 'graph': {},"
        " 'nodes': [{'id': r['id']} for r in records], 'edges': []}",
        "domain.cubes.relations_match_geometry",
    ),
}


@pytest.mark.parametrize("function", list(DEGENERATE))
def test_degenerate_outputs_fail_the_checks_that_need_them(rivet_check, function):
    """No records, no steps, blank renders, no relations: "passed" needs every required check
    to have run and passed, so the check that needs real output fails (it is not skipped)."""
    body, needs = DEGENERATE[function]
    source = (
        "import numpy as np\nRELATIONS = {'on': 'the first rests on the second'}\n"
        f"def {function}({SIGNATURES[function]}):\n    {body}\n"
    )
    code, report, _ = rivet_check(function, source)
    assert code == 1 and report["passed"] is False
    check = next(c for c in report["checks"] if c["name"] == needs)
    assert check["status"] == "failed", check
