"""The local backend: the same verdicts as Docker, without isolation, and it says so."""

from __future__ import annotations

import os

import numpy as np
import pytest

from sandbox import BadJob, Job
from sandbox.local_backend import WARNING, LocalExecutor

HELPER = "def double(x):\n    return 2 * x\n"


def run(executor, source: str, **kw):
    return executor.run(Job(source=source, function=kw.pop("function", "f"), **kw))


def test_it_warns_that_it_isolates_nothing(capsys):
    with LocalExecutor(preload="none") as ex:
        assert run(ex, "def f():\n    return 1\n").ok
    assert WARNING in capsys.readouterr().err
    assert "isolates NOTHING" in WARNING


def test_ok_with_arrays_modules_and_stdout(local_executor):
    source = "import helper\ndef f(a, k):\n    print('hello')\n    return {'b': helper.double(a), 'k': k}\n"
    report = run(
        local_executor,
        source,
        inputs={"a": np.arange(3.0), "k": [1, "x"]},
        modules={"helper": HELPER},
    )
    assert report.verdict == "ok", report
    assert np.array_equal(report.output["b"], [0.0, 2.0, 4.0]) and report.output["k"] == [1, "x"]
    assert report.stdout_tail == "hello\n" and report.stdout_bytes == 6
    assert report.wall_time_s > 0 and report.backend == "local"


def test_exception_traceback_shows_only_the_draft(local_executor):
    source = "import helper\ndef f():\n    return helper.boom()\n"
    helper = "def boom():\n    raise KeyError('missing')\n"
    report = run(local_executor, source, modules={"helper": helper})
    assert report.verdict == "exception"
    assert report.exception.type == "KeyError" and report.exception.message == "'missing'"
    tb = report.exception.traceback
    assert 'File "draft.py", line 3, in f' in tb and 'File "helper.py", line 2, in boom' in tb
    assert "child.py" not in tb and "server.py" not in tb


def test_syntax_errors_point_at_the_draft_line(local_executor):
    report = run(local_executor, "def f():\n    return (\n")
    assert report.verdict == "exception" and report.exception.type == "SyntaxError"
    assert "draft.py" in report.exception.traceback


def test_missing_function_is_an_exception(local_executor):
    report = run(local_executor, "x = 1\n", function="render")
    assert report.verdict == "exception" and "no function 'render'" in report.exception.message


@pytest.mark.parametrize(
    ("source", "verdict", "detail"),
    [
        ("import time\ndef f():\n    time.sleep(60)\n", "timeout", "time budget"),
        ("def f():\n    return bytearray(1 << 34)\n", "oom", "memory limit"),
        ("import os\ndef f():\n    os.abort()\n", "crashed", "SIGABRT"),
        ("import os\ndef f():\n    os._exit(3)\n", "crashed", "code 3"),
        ("def f():\n    return {'m': lambda: 1}\n", "bad_output", "output.m: builtins.function"),
    ],
)
def test_each_verdict(local_executor, source, verdict, detail):
    report = run(local_executor, source, timeout_s=1, memory_mb=128)
    assert report.verdict == verdict, report
    assert detail in report.detail


def test_output_schema_is_checked_on_the_host(local_executor):
    schema = {"type": "object", "properties": {"n": {"type": "integer"}}, "required": ["n"]}
    bad = run(local_executor, "def f():\n    return {'n': 'three'}\n", output_schema=schema)
    assert bad.verdict == "bad_output" and "output.n" in bad.detail
    assert run(local_executor, "def f():\n    return {'n': 3}\n", output_schema=schema).ok


def test_a_session_answers_calls_in_order_with_their_errors(local_executor):
    from sandbox import Program

    source = "def f(x):\n    if x < 0:\n        raise ValueError('negative')\n    return x * x\n"
    with local_executor.open_session(Program(modules={"prog": source})) as session:
        answers = [session.call("prog", "f", x, timeout_s=5) for x in (2, -1, 3)]
    assert [a.value for a in answers] == [4, None, 9]
    assert answers[1].verdict == "exception" and answers[1].exception.message == "negative"


def test_a_calls_arrays_come_through_a_file_that_is_gone_once_it_answers(local_executor):
    from sandbox import Program

    source = (
        "import os\n"
        "def f(image, scale, args):\n"
        "    seen = sorted(os.listdir(args))\n"
        "    image *= scale\n"  # the program may write to its arguments
        "    return {'image': image, 'seen': seen}\n"
    )
    image = np.arange(12, dtype=np.float32).reshape(3, 4)
    with local_executor.open_session(Program(modules={"prog": source})) as session:
        args = session.staged / "args"  # the local harness sees the host's paths
        first = session.call("prog", "f", image, 2.0, str(args), timeout_s=5)
        second = session.call("prog", "f", image, 3.0, str(args), timeout_s=5)
        assert first.ok and second.ok, (first, second)
        assert first.value["seen"] == ["c1.npz"] and second.value["seen"] == ["c2.npz"]
        assert not any(args.iterdir()), "a call's arrays outlived its answer"
    assert np.array_equal(first.value["image"], 2 * image)
    assert np.array_equal(second.value["image"], 3 * image)
    assert np.array_equal(image, np.arange(12, dtype=np.float32).reshape(3, 4))


def test_unsendable_inputs_are_the_callers_mistake(local_executor):
    with pytest.raises(BadJob, match=r"arguments\.kwargs\.x"):
        run(local_executor, "def f(x):\n    return x\n", inputs={"x": object()})


def test_escaped_children_are_killed_after_the_job(local_executor):
    source = (
        "import os, subprocess\n"
        "def f():\n"
        "    p = subprocess.Popen(['sleep', '1000'], start_new_session=True)\n"
        "    return p.pid\n"
    )
    report = run(local_executor, source)
    assert report.ok
    with pytest.raises(ProcessLookupError):
        os.kill(report.output, 0)


def test_a_killed_harness_gives_crashed_and_a_fresh_one(local_executor):
    source = "import os, signal\ndef f():\n    os.kill(os.getppid(), signal.SIGKILL)\n    import time; time.sleep(5)\n"
    before = local_executor.restarts
    report = run(local_executor, source)
    assert report.verdict == "crashed" and "harness died" in report.detail
    assert run(local_executor, "def f():\n    return 7\n").output == 7
    assert local_executor.restarts == before + 1


def test_a_small_memory_limit_still_runs_small_jobs(local_executor):
    source = "def f(n):\n    return len(bytearray(n))\n"
    assert run(local_executor, source, inputs={"n": 8 << 20}, memory_mb=32).output == 8 << 20
    report = run(local_executor, source, inputs={"n": 64 << 20}, memory_mb=32)
    assert report.verdict == "oom" and 'File "draft.py", line 2' in report.exception.traceback


def test_a_call_that_ended_with_the_process_is_still_judged():
    """A process that exited with its answer has no threads left to read a CPU wait from:
    the wait is zero, not a harness error (it was one, now and then, on a busy machine)."""
    from types import SimpleNamespace

    from sandbox.harness.server import _Child

    gone = SimpleNamespace(run_delays=dict)
    assert _Child.queued_seconds(gone, {"7": 5}) == 0.0
    running = SimpleNamespace(run_delays=lambda: {"7": 3_000_000_000, "8": 10})
    assert _Child.queued_seconds(running, {"7": 1_000_000_000}) == 2.0
