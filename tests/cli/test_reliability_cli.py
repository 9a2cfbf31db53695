"""`rivet eval cubes --policy runs RUNS_DIR --pairs K`: a reliability study end to end.

The runs folder is made by the real authoring loop (`agent.loop.AuthoringRun`, with the
journal and run layout `rivet author cubes --runs N --runs-dir RUNS_DIR` writes:
RUNS_DIR/cubes/<stamp>/{journal.jsonl, responses/, drafts/, reports/, frozen/}), offline: a
scripted model answers with the people-written reference programs of domains/cubes/programs,
and a pass-through checker stands in for the check suite (hand-made for this test — the
study reads only the journal and `frozen/`; the real checks are tested elsewhere). Three runs:

1. the reference programs: every pair solved;
2. the reference programs with a hand-made `plan` that gives up ("infeasible"): perception
   right, no plan — this shows each run is evaluated with its own programs;
3. a run whose `plan` never passes its (stand-in) checks: authoring exhausted, no programs.

The study runs on the first K = 1 dev pair with `--sandbox local`, and the per-run and pooled
counts are checked in the printed table and in `--json`.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from agent.clients import ScriptedClient
from agent.errors import AuthoringExhausted
from agent.journal import Journal, new_run_dir
from agent.loop import AuthoringRun
from agent.prompt import DomainContext
from contracts.functions import authoring_order
from rivet.cli import main

REPO = Path(__file__).resolve().parents[2]
RIVET = str(Path(sys.executable).parent / "rivet")
PROGRAMS = REPO / "domains" / "cubes" / "programs"
K = 1

CONTEXT = DomainContext(domain="cubes", task="(test)", cameras="(test)", meshes="(test)")
GIVE_UP = (
    "def plan(start_state, goal_state, *more):\n"
    "    return {'status': 'infeasible', 'reason': 'hand-made for the test: this run gives up'}\n"
)
NEVER_PASSES = "# hand-made: fails its checks\n"


class PassThroughChecker:
    """Hand-made stand-in for the check suite: passes every draft but one marked to fail."""

    def check(self, domain, function, source, *, deps, out_dir: Path, cases_seed=None) -> dict:
        ok = NEVER_PASSES not in source
        return {
            "schema_version": 1,
            "domain": domain,
            "function": function,
            "passed": ok,
            "first_failure": None if ok else "stand_in",
            "checks": [
                {"name": "stand_in", "category": "property", "status": "passed" if ok else "failed"}
            ],
        }

    def markdown(self, report: dict) -> str:
        return f"stand_in: {report['checks'][0]['status']}"


def answer(source: str) -> str:
    return f"```python\n{source}```\n"


def author(runs_dir: Path, sources: dict[str, str], *, attempts: int = 4) -> Path:
    """One authoring run, the loop `rivet author` drives, answered by `sources`."""
    run_dir = new_run_dir(runs_dir, "cubes")
    client = ScriptedClient([answer(sources[f]) for f in authoring_order()])
    AuthoringRun(
        ctx=CONTEXT,
        client=client,
        checker=PassThroughChecker(),
        journal=Journal(run_dir),
        max_attempts=attempts,
        progress=lambda _: None,
    ).run()
    return run_dir


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    runs = tmp_path_factory.mktemp("study") / "runs"
    reference = {f: (PROGRAMS / f"{f}.py").read_text() for f in authoring_order()}
    good = author(runs, reference)
    gives_up = author(runs, {**reference, "plan": GIVE_UP})
    with pytest.raises(AuthoringExhausted):
        author(runs, {**reference, "plan": NEVER_PASSES + reference["plan"]}, attempts=1)
    exhausted = sorted((runs / "cubes").iterdir())[-1]
    # folders of runs that never started: no journal; a journal refused before any call
    (runs / "cubes" / "0-no-journal").mkdir()
    (runs / "cubes" / "0-no-call").mkdir()
    (runs / "cubes" / "0-no-call" / "journal.jsonl").write_text(
        json.dumps({"event": "started", "config": {"domain": "cubes"}}) + "\n"
    )
    out = runs.parent / "study.json"
    proc = subprocess.run(
        [
            RIVET,
            "eval",
            "cubes",
            "--policy",
            "runs",
            str(runs),
            "--pairs",
            str(K),
            "--sandbox",
            "local",
            "--quiet",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=REPO,
    )
    names = {p: str(p.relative_to(runs)) for p in (good, gives_up, exhausted)}
    return (
        proc,
        json.loads(out.read_text()) if out.is_file() else None,
        names,
        (good, gives_up, exhausted),
    )


def test_each_run_is_evaluated_on_the_first_k_pairs_and_pooled(study):
    proc, data, names, (good, gives_up, exhausted) = study
    assert proc.returncode == 1, proc.stderr[-3000:]  # a failed run and failed pairs: exit 1
    assert data is not None, proc.stderr[-3000:]
    assert data["pairs"] == K and data["pair_names"] == ["goal01_start1"]
    assert (data["total_runs"], data["finished_runs"]) == (3, 2)
    rows = {r["run"]: r for r in data["runs"]}
    assert list(rows) == sorted(names.values())

    ok = rows[names[good]]
    assert ok["finished"]
    assert {k: ok["counts"][k] for k in ("trials", "state_ok", "plan_ok", "final_ok")} == {
        "trials": K,
        "state_ok": K,
        "plan_ok": K,
        "final_ok": K,
    }
    assert ok["summary"]["policy"] == f"run {good}"  # its own programs, in its own session

    bad = rows[names[gives_up]]
    assert bad["finished"] and bad["failures"] == {"planning": K}
    assert (bad["counts"]["state_ok"], bad["counts"]["plan_ok"], bad["counts"]["final_ok"]) == (
        K,
        0,
        0,
    )

    failed = rows[names[exhausted]]
    assert not failed["finished"] and failed["counts"] is None
    assert "authoring exhausted: plan failed all 1 attempts" in failed["reason"]
    assert "frozen: render, perceive, relate" in failed["reason"]

    # pooled over all runs: the failed run's pairs count as failures
    pooled = data["pooled"]
    assert (pooled["runs"], pooled["trials"]) == (3, 3 * K)
    assert (pooled["state_ok"], pooled["plan_ok"], pooled["final_ok"]) == (2 * K, K, K)
    fin = data["pooled_finished"]
    assert (fin["runs"], fin["trials"]) == (2, 2 * K)
    assert (fin["state_ok"], fin["plan_ok"], fin["final_ok"]) == (2 * K, K, K)
    assert data["runs_solving_every_pair"] == 1
    # the runs that never started are listed apart, counted nowhere
    assert [r["run"] for r in data["never_started"]] == ["cubes/0-no-call", "cubes/0-no-journal"]
    assert "journal holds no call" in data["never_started"][0]["reason"]

    table = proc.stdout
    assert "not counted: 2 folder(s) of runs that never started" in table
    assert f"3 runs × {K} pairs" in table
    assert f"{names[exhausted]}" in table and "FAILED" in table
    pooled_row = next(line for line in table.splitlines() if "pooled, all 3 runs" in line)
    assert f"{2 * K}/{3 * K}  66.7%" in pooled_row and f"{K}/{3 * K}  33.3%" in pooled_row
    finished_row = next(line for line in table.splitlines() if "pooled, 2 finished runs" in line)
    assert f"{2 * K}/{2 * K} 100.0%" in finished_row and f"{K}/{2 * K}  50.0%" in finished_row


def test_usage_errors_name_the_problem(tmp_path, capsys):
    def rivet(*args: str) -> tuple[int, str]:  # the command line's entry point, in process
        capsys.readouterr()
        code = main(["eval", "cubes", *args])
        return code, capsys.readouterr().err

    code, err = rivet("--policy", "runs", str(tmp_path))
    assert code == 2 and "no authoring runs of cubes" in err
    code, err = rivet("--policy", "runs", str(tmp_path), "--trials", "3")
    assert code == 2 and "--pairs K" in err
    code, err = rivet("--policy", "artifacts", "--pairs", "3")
    assert code == 2 and "--policy runs RUNS_DIR --pairs K" in err
    code, err = rivet("--policy", "runs", str(tmp_path), "--view", "all")
    assert code == 2 and "one camera" in err


def test_every_run_folder_is_a_run_finished_or_failed_with_its_reason(tmp_path):
    """Hand-made run folders (journals written here, not by the loop) for the cases a study
    must report rather than skip; also the `--ray` layout and the `<domain>/` folder itself."""
    from artifacts.policy import find_runs

    def journal(folder: Path, *events: dict) -> None:
        folder.mkdir(parents=True)
        (folder / "journal.jsonl").write_text("".join(json.dumps(e) + "\n" for e in events))

    started = {"event": "started", "config": {"domain": "cubes"}}
    runs = tmp_path / "runs"
    journal(
        runs / "cubes" / "a-killed", started, {"event": "call", "function": "render", "attempt": 1}
    )
    (runs / "cubes" / "b-no-journal").mkdir()
    journal(runs / "cubes" / "c-no-plan", started, {"event": "finished"})
    journal(runs / "cubes" / "d-tangram", {"event": "started", "config": {"domain": "tangram"}})
    done = runs / "ray-001" / "cubes" / "e-done"
    journal(done, started, {"event": "finished"})
    (done / "frozen").mkdir()
    for f in authoring_order():
        (done / "frozen" / f"{f}.py").write_text(f"def {f}(*a):\n    pass\n")
    (runs / "cubes" / "c-no-plan" / "frozen").mkdir()
    (runs / "cubes" / "c-no-plan" / "frozen" / "render.py").write_text("")

    found = {r.name: r for r in find_runs("cubes", runs)}
    assert sorted(found) == [
        "cubes/a-killed",
        "cubes/b-no-journal",
        "cubes/c-no-plan",
        "cubes/d-tangram",
        "ray-001/cubes/e-done",
    ]
    assert "the journal ends with 'call' render attempt 1" in found["cubes/a-killed"].reason
    assert "the run never started" in found["cubes/b-no-journal"].reason
    assert "frozen/ lacks perceive.py, relate.py, plan.py" in found["cubes/c-no-plan"].reason
    assert "a run of tangram" in found["cubes/d-tangram"].reason
    ok = found["ray-001/cubes/e-done"]
    assert ok.finished and ok.reason is None and ok.policy == ("run", str(done))
    assert [r.policy for n, r in found.items() if n != ok.name] == [None] * 4
    assert [n for n, r in found.items() if not r.started] == ["cubes/b-no-journal"]
    # the <domain>/ folder itself names its runs without the prefix
    assert [r.name for r in find_runs("cubes", runs / "cubes")][:2] == ["a-killed", "b-no-journal"]
