"""`rivet eval` from the command line: `--view all` on the frozen artifacts gives one summary
per camera, each naming the set hash of the programs it ran (so a result can be traced to the
artifacts that produced it); the options' validation, signals and `--resume`."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
RIVET = str(Path(sys.executable).parent / "rivet")


def test_every_view_summary_names_the_evaluated_set_and_the_run(tmp_path):
    out = tmp_path / "eval.json"
    proc = subprocess.run(
        [
            RIVET,
            "eval",
            "cubes",
            "--policy",
            "artifacts",
            "--trials",
            "1",
            "--view",
            "all",
            "--fit",
            "--quiet",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=REPO,
    )
    assert proc.returncode in (0, 1), proc.stderr[-2000:]
    manifest = json.loads((REPO / "artifacts" / "cubes" / "manifest.json").read_text())
    summaries = json.loads(out.read_text())["cubes"]
    assert sorted(summaries) == ["front", "view1", "view2"]
    for view, summary in summaries.items():
        assert summary["view"] == view and summary["trials"] == 1
        assert summary["set_hash"] == manifest["set_hash"]
        run = summary["run"]  # what produced it: docs/results.md cites these
        assert run["command"] == (
            f"rivet eval cubes --policy artifacts --trials 1 --view all --fit --quiet --json {out}"
        )
        assert re.fullmatch(r"[0-9a-f]{12}", run["commit"]) and isinstance(run["dirty"], bool)
        assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", run["date"])
        assert run["wall_s"] > 0
        (trial,) = summary["per_trial"]  # --fit: how well each perceived state explains its image
        assert sorted(trial["fit"]) == ["goal", "start"] and trial["fit"]["start"]["ok"], trial


def _one_oracle_trial(tmp_path, *options: str) -> list[str]:
    """Names of the trials `rivet eval cubes --policy oracle OPTIONS --trials 1` ran; asserts
    that the run left the set's benchmark figures (eval.json) alone."""
    out = tmp_path / "eval.json"
    eval_json = REPO / "artifacts" / "cubes" / "eval.json"
    before = eval_json.read_bytes() if eval_json.is_file() else None
    proc = subprocess.run(
        [
            *(RIVET, "eval", "cubes", "--policy", "oracle", *options),
            *("--trials", "1", "--quiet", "--json", str(out)),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=REPO,
    )
    assert proc.returncode in (0, 1), proc.stderr[-2000:]
    assert (eval_json.read_bytes() if eval_json.is_file() else None) == before
    return [t["name"] for t in json.loads(out.read_text())["per_trial"]]


def test_a_fresh_seed_draws_from_the_split_asked_for(tmp_path):
    """`--seed S --split test` runs fresh test-split instances (named test/seedS), not dev ones,
    and a fresh set, even from seed 0, never writes the set's benchmark figures (eval.json)."""
    assert _one_oracle_trial(tmp_path, "--split", "test", "--seed", "0") == ["test/seed0"]


def test_composed_goals_run_as_instances_and_a_domain_without_a_composer_is_refused(tmp_path):
    """`--composed S` runs goals composed outside every catalogue (named composed/seedS, the
    first seeds that give an instance) and never writes the benchmark figures; a domain with no
    composer exits 2 saying so, and so does `--composed` beside `--seed`."""
    assert _one_oracle_trial(tmp_path, "--composed", "2000") == ["composed/seed2000"]
    from contracts.errors import UsageError
    from rivet.commands._trials import _composed

    class Plain:  # a user's domain that composes nothing (`Domain.compose` as inherited)
        name = "plain"

        def composed_instance(self, seed):
            return None

    with pytest.raises(UsageError, match="plain composes no goals"):
        _composed(Plain(), 1, 2)
    proc = subprocess.run(
        [RIVET, "eval", "cubes", "--policy", "oracle", "--seed", "1", "--composed", "1"],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=REPO,
    )
    assert proc.returncode == 2 and "--seed, --composed: pick one" in proc.stderr


@pytest.mark.parametrize(
    ("argv", "realism", "in_hand", "tracked", "warned"),
    [
        ([], "default", "wrist", False, False),
        (["--protocol", "oracle-sensing"], "clean", "exact", True, False),
        (["--protocol", "previous"], "clean", "exact", True, True),  # its old name
        (["--protocol", "oracle-sensing", "--realism", "harsh"], "harsh", "exact", True, False),
    ],
)
def test_the_protocol_options_name_what_the_robot_senses(
    argv, realism, in_hand, tracked, warned, capsys
):
    from rivet.cli import build_parser
    from rivet.commands._trials import protocol_of

    protocol = protocol_of(build_parser().parse_args(["eval", "cubes", *argv]))
    assert (protocol.realism, protocol.in_hand, protocol.track_objects) == (
        realism,
        in_hand,
        tracked,
    )
    assert ("now --protocol oracle-sensing" in capsys.readouterr().err) == warned


def test_the_camera_offset_estimate_can_be_switched_off():
    from rivet.cli import build_parser
    from rivet.commands._trials import protocol_of

    on = protocol_of(build_parser().parse_args(["eval", "cubes"]))
    off = protocol_of(build_parser().parse_args(["eval", "cubes", "--no-camera-offset"]))
    assert on.executor_config().camera_offset and not off.executor_config().camera_offset
    assert "camera-offset" not in on.label and "no camera-offset estimate" in off.label


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["cubes", "--trials", "0"], "--trials: must be at least 1, got 0"),
        (["cubes", "--trials", "-1"], "--trials: must be at least 1, got -1"),
        (["cubes", "--workers", "0"], "--workers: must be at least 1, got 0"),
        (["cubes", "--seed", "-3"], "--seed: must be at least 0, got -3"),
        (["--trials", "1"], "name a DOMAIN or pass --all"),
        (
            ["cubes", "--policy", "artifacts", "cubes"],
            "--policy artifacts cubes: no frozen cubes set",
        ),
        (["cubes", "--faults", "push,shove"], "--faults: unknown fault 'shove'; known: slip"),
        (["cubes", "--loop", "closed", "--policy", "oracle"], "--loop closed needs programs"),
        (["cubes", "--loop", "sideways"], "invalid choice: 'sideways'"),
    ],
)
def test_bad_numbers_and_a_missing_domain_exit_2_naming_them(argv, message, capsys):
    from rivet.cli import main

    try:
        code = main(["eval", *argv])
    except SystemExit as e:  # argparse's own errors
        code = int(e.code or 0)
    err = capsys.readouterr().err
    assert code == 2 and message in err, err
    assert "Traceback" not in err


def test_a_robot_model_that_does_not_load_stops_before_any_trial(tmp_path, monkeypatch):
    """MENAGERIE_ROOT pointing nowhere was scored as a 0 % table of failed trials, then the
    cause; now the cause, exit 2, and no trial."""
    import subprocess

    env = {**__import__("os").environ, "MENAGERIE_ROOT": str(tmp_path / "nowhere")}
    proc = subprocess.run(
        [RIVET, "eval", "cubes", "--policy", "oracle", "--trials", "1", "--quiet"],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
        env=env,
    )
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "the simulator cannot run: cannot load menagerie model" in proc.stderr
    assert "final_sr" not in proc.stdout and "Traceback" not in proc.stderr


@pytest.mark.docker
@pytest.mark.slow
def test_sigterm_stops_an_evaluation_like_ctrl_c_and_removes_its_containers(tmp_path):
    """A cancelled CI job sends SIGTERM: the evaluation unwinds as on Ctrl-C (exit 143,
    "terminated"), and the policy's sandbox container is removed, not left exited."""
    import signal
    import subprocess
    import time

    import docker

    proc = subprocess.Popen(
        [RIVET, "eval", "cubes", "--policy", "artifacts", "--trials", "5", "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
    )
    client = docker.from_env()

    def owned() -> list:
        listed = client.containers.list(all=True, filters={"label": "rivet.sandbox=1"})
        return [
            c
            for c in listed
            if c.labels.get("rivet.sandbox.owner", "").split(":")[1:2] == [str(proc.pid)]
        ]

    deadline = time.monotonic() + 120
    while not owned() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.5)
    assert owned(), "the evaluation never started its sandbox"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err[-2000:]
    assert "terminated" in err and "Traceback" not in err, err[-2000:]
    assert owned() == [], [c.name for c in owned()]


@pytest.mark.slow
def test_an_interrupted_evaluation_keeps_its_trials_and_resume_runs_only_the_rest(tmp_path):
    import signal
    import time

    out = tmp_path / "oracle.json"
    log = tmp_path / "oracle.cubes.front.trials.jsonl"
    argv = [RIVET, "eval", "cubes", "--policy", "oracle", "--trials", "3", "--json", str(out)]
    proc = subprocess.Popen(
        [*argv, "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
        # Ctrl-C's default, as in a terminal: a suite started as a background job (`make test &`
        # in a script) passes SIGINT on ignored, and a Python started so ignores it too
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    lines: list[str] = []
    while proc.poll() is None and len(lines) < 2:  # the header and one finished trial
        time.sleep(0.2)
        lines = log.read_text().splitlines() if log.is_file() else []
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err[-2000:]
    assert f"the finished trials are kept in {log}" in err and "Traceback" not in err
    kept = [json.loads(line) for line in log.read_text().splitlines()]
    assert kept[0]["evaluation"]["trials"][:1] == ["goal01_start1"] and len(kept) in (2, 3)
    assert not out.exists()

    again = subprocess.run([*argv, "--resume"], capture_output=True, text=True, cwd=REPO)
    assert again.returncode in (0, 1), again.stderr[-2000:]
    assert f"{len(kept) - 1} of 3 trials kept" in again.stderr
    summary = json.loads(out.read_text())
    assert [t["name"] for t in summary["per_trial"]] == kept[0]["evaluation"]["trials"]
    assert summary["per_trial"][0] == kept[1]  # kept, not run again
    assert len(log.read_text().splitlines()) == 4  # header + 3 trials, none twice

    other = subprocess.run(  # a log of another evaluation is refused, not mixed in
        [*argv, "--resume", "--loop", "open", "--faults", "push"],
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    assert other.returncode == 2 and "is the log of another evaluation" in other.stderr


def test_sigterm_stops_a_pool_of_workers_at_once_and_keeps_the_finished_trials(tmp_path):
    """SIGTERM to `rivet eval --workers 2` alone (a CI job cancelled; the workers get no
    signal of their own): the trials not begun are cancelled and the running ones end now — the
    log holds at most the trials finished by then, not all four — and no worker outlives it."""
    import signal
    import time

    out = tmp_path / "oracle.json"
    log = tmp_path / "oracle.cubes.front.trials.jsonl"
    argv = [RIVET, "eval", "cubes", "--policy", "oracle", "--trials", "4", "--workers", "2"]
    proc = subprocess.Popen(
        [*argv, "--json", str(out), "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
    )
    lines: list[str] = []
    while proc.poll() is None and len(lines) < 2:  # the header and one finished trial
        time.sleep(0.2)
        lines = log.read_text().splitlines() if log.is_file() else []
    workers = [
        int(p.name)
        for p in Path("/proc").iterdir()
        if p.name.isdigit() and _parent(p) == proc.pid and "spawn_main" in _cmdline(p)
    ]
    assert len(workers) == 2
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err[-2000:]
    assert f"the finished trials are kept in {log}" in err and "Traceback" not in err
    assert 2 <= len(log.read_text().splitlines()) <= 3  # one trial, or the other one's too
    assert not any(Path(f"/proc/{pid}").exists() and _parent(Path(f"/proc/{pid}")) != 0
                   for pid in workers)  # fmt: skip
    assert not out.exists()


def _parent(proc_dir: Path) -> int:
    try:
        return int((proc_dir / "stat").read_text().rsplit(")", 1)[1].split()[1])
    except (OSError, IndexError, ValueError):
        return 0


def _cmdline(proc_dir: Path) -> str:
    try:
        return (proc_dir / "cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""
