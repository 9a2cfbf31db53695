"""A run killed with SIGKILL mid-run resumes: nothing frozen is lost, no response is asked twice."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

SCRIPT = textwrap.dedent(
    """
    import json, os, signal, sys
    from pathlib import Path
    sys.path.insert(0, {tests!r})
    from agent.clients import ScriptedClient
    from agent.journal import Journal
    from agent.loop import AuthoringRun
    from conftest import CONTEXT, ToyChecker, good, bad

    run_dir, kill_at_check, log = Path(sys.argv[1]), int(sys.argv[2]), Path(sys.argv[3])
    replies = [good("render"), bad("perceive"), good("perceive"), good("relate"), good("plan")]

    class Logged(ScriptedClient):
        def complete(self, request):
            with open(log, "a") as f:
                f.write(json.dumps([request.function, request.attempt]) + "\\n")
            return super().complete(request)

    done = {{(e["function"], e["attempt"]) for e in Journal(run_dir).events() if e["event"] == "response"}}
    queue = [r for r, key in zip(replies, [("render", 1), ("perceive", 1), ("perceive", 2), ("relate", 1), ("plan", 1)]) if key not in done]

    class Killing(ToyChecker):
        def check(self, *a, **kw):
            self.n = getattr(self, "n", 0) + 1
            if self.n == kill_at_check:
                os.kill(os.getpid(), signal.SIGKILL)
            return super().check(*a, **kw)

    frozen = AuthoringRun(ctx=CONTEXT, client=Logged(queue), checker=Killing(),
                          journal=Journal(run_dir), progress=lambda _: None).run()
    print(json.dumps(sorted(frozen)))
    """
)


def test_sigkill_mid_run_then_resume(tmp_path):
    tests = str(Path(__file__).parent)
    script = tmp_path / "author.py"
    script.write_text(SCRIPT.format(tests=tests))
    run_dir, log = tmp_path / "run", tmp_path / "calls.log"
    env = {
        "PATH": "/usr/bin:/bin",
        "RIVET_FORBID_MODEL_API": "1",
        "PYTHONPATH": str(Path(tests).parents[1]),
    }

    # killed during the 3rd check (perceive attempt 2): render frozen, 3 responses saved
    first = subprocess.run(
        [sys.executable, str(script), str(run_dir), "3", str(log)],
        env=env,
        capture_output=True,
        text=True,
    )
    assert first.returncode == -9, first.stderr
    asked_first = [tuple(json.loads(line)) for line in log.read_text().splitlines()]
    assert asked_first == [("render", 1), ("perceive", 1), ("perceive", 2)]
    assert (run_dir / "frozen" / "render.py").is_file()

    log.unlink()
    second = subprocess.run(
        [sys.executable, str(script), str(run_dir), "0", str(log)],
        env=env,
        capture_output=True,
        text=True,
    )
    assert second.returncode == 0, second.stderr
    assert json.loads(second.stdout) == ["perceive", "plan", "relate", "render"]
    asked_second = [tuple(json.loads(line)) for line in log.read_text().splitlines()]
    assert asked_second == [("relate", 1), ("plan", 1)]  # nothing asked twice
    frozen_events = [
        e
        for e in map(json.loads, (run_dir / "journal.jsonl").read_text().splitlines())
        if e["event"] == "frozen"
    ]
    assert [e["function"] for e in frozen_events] == ["render", "perceive", "relate", "plan"]
