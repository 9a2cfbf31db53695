"""docs/results.md is generated: the committed page is what the committed run files render, each
run file is the output of the command the page lists for it, and every rate carries its
interval."""

from __future__ import annotations

import json
import re

import pytest

from experiments import results
from experiments.evaluation import wilson


def _files() -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in sorted(results.RUN_FILES.glob("*.json"))}


def test_the_committed_page_is_what_the_run_files_render():
    assert results.PAGE.read_text() == results.render(), (
        "docs/results.md is not what docs/results/ renders: run `make results`"
    )


def test_the_page_is_a_reference_of_at_most_300_lines_with_an_interval_on_every_rate():
    page = results.render()
    assert len(page.splitlines()) <= 300
    bare = [line for line in page.splitlines() for _ in re.finditer(r"\d+\.\d %(?! \(\d)", line)]
    assert not bare, f"a rate without its interval: {bare[:3]}"
    assert not re.search(r"(first|second|third|[0-9]+th) session", page, re.IGNORECASE)


def test_every_run_file_is_a_listed_command_and_its_rates_are_its_trials():
    runs = {r.key: r for r in results.runs()}
    for key, run in _files().items():
        assert key in runs, f"docs/results/{key}.json is no command of the page"
        if runs[key].tool == "checks":
            summary = run["summary"]
            assert summary["run"]["command"] == runs[key].command, key
            assert summary["caught"] == sum(m["caught"] for m in run["mutants"]), key
            continue
        assert run["run"]["command"] == runs[key].command, key
        assert re.fullmatch(r"[0-9a-f]{12}", run["run"]["commit"]), key
        trials = run["per_trial"]
        assert run["trials"] == len(trials) > 0, key
        for rate, verdict in (
            ("state_ac", "state_ok"),
            ("plan_sr", "plan_ok"),
            ("final_sr", "final_ok"),
        ):
            k = sum(t[verdict] for t in trials)
            assert run[rate] == pytest.approx(k / len(trials)), (key, rate)
            assert run["intervals"][rate] == pytest.approx(list(wilson(k, len(trials)))), key
        assert all(t["final_ok"] for t in trials if "failure" not in t), key  # failures named


def test_a_run_file_keeps_each_trials_verdict_and_refuses_an_unattributed_summary():
    summary = {
        "domain": "cubes",
        "trials": 1,
        "state_ac": 0.0,
        "plan_sr": 0.0,
        "final_sr": 0.0,
        "intervals": {k: [0.0, 0.79] for k in ("state_ac", "plan_sr", "final_sr")},
        "per_trial": [
            {
                "name": "test/goal01_start1",
                "state_ok": False,
                "plan_ok": False,
                "final_ok": False,
                "failure": {"stage": "perception", "reason": "x" * 500},
                "timings": {"total": 3.14159},
                "steps": [{"large": "detail"}],
            }
        ],
    }
    with pytest.raises(ValueError, match="names no command"):
        results.compact(summary)
    kept = results.compact({**summary, "run": {"command": "rivet eval cubes"}})
    (trial,) = kept["per_trial"]
    assert trial["failure"]["stage"] == "perception" and trial["wall_s"] == 3.14
    assert len(trial["failure"]["reason"]) == results.REASON_CHARS + 1  # the cut is marked: …
    assert "steps" not in trial


def test_an_unknown_run_is_refused_naming_the_known_ones(capsys):
    assert results.main(["run", "cubes-nowhere"]) == 2
    assert "unknown run cubes-nowhere" in capsys.readouterr().err


def test_a_checks_benchmark_is_kept_and_shown_with_its_interval_and_missed_mutants(tmp_path):
    run = {
        "command": "python -m benchmarks.checks_bench --domain cubes --repeats 10 --out "
        "runs/results/checks-cubes",
        "commit": "0123456789ab",
        "dirty": False,
        "date": "2026-12-06T12:00:00Z",
        "cpus": 2,
    }
    bench = {
        "summary": {
            "domain": "cubes",
            "mutants": 3,
            "caught": 2,
            "caught_rate": 0.6667,
            "correct_runs": 40,
            "false_rejections": 0,
            "all_reports_identical": True,
            "seconds_per_check_median": 4.0,
            "seconds_per_check_max": 17.5,
            "wall_s": 600.0,
            "run": run,
        },
        "correct": [
            {
                "function": "plan",
                "runs": 10,
                "rejections": 0,
                "identical_reports": True,
                "rejected_by": [],
                "cases_seed": 1,
            }
        ],
        "mutants": [
            {
                "mutant": m,
                "function": "plan",
                "caught": c,
                "first_failure": None,
                "seconds": 1.0,
                "failing": [],
                "bug": "b",
            }
            for m, c in (("a", True), ("b", True), ("plan_missed", False))
        ],
        "field": [
            {
                "program": "cubes_perceive_run1",
                "function": "perceive",
                "path": "/somewhere/cubes_perceive_run1.py",
                "draws": 5,
                "rejected": 3,
                "case": "perceive is wrong on obs19",
                "draw_rows": [
                    {"cases_seed": 7, "rejected": False, "case": None},
                    {"cases_seed": 8, "rejected": True, "case": "perceive is wrong on obs19"},
                ],
            }
        ],
    }
    results.write("checks-cubes", bench, tmp_path)
    kept = json.loads((tmp_path / "checks-cubes.json").read_text())
    assert "bug" not in kept["mutants"][0] and kept["summary"]["run"] == run
    assert kept["field"] == [
        {"program": "cubes_perceive_run1", "function": "perceive", "draws": 5, "rejected": 3,
         "case": "perceive is wrong on obs19"}
    ]  # fmt: skip
    page = results.render(tmp_path, names=["cubes"])
    (row,) = [line for line in page.splitlines() if line.startswith("| cubes | 2/3")]
    assert "66.7 % (20.8–93.9)" in row and "`plan_missed`" in row and "0 of 40 runs" in row
    assert row.endswith("| `cubes_perceive_run1` 3 of 5 |")
    assert "- `cubes_perceive_run1`: perceive is wrong on obs19" in page
    assert "| checks-cubes | `python -m benchmarks.checks_bench --domain cubes" in page
    assert "| 2026-12-06 12:00 | 0123456789ab | – | 10.0 min |" in page


def test_a_run_of_a_set_that_is_no_longer_committed_is_marked(tmp_path):
    kept = json.loads((results.RUN_FILES / "cubes-dev-front.json").read_text())
    (tmp_path / "cubes-dev-front.json").write_text(json.dumps(kept))
    page = results.render(tmp_path, names=["cubes"])
    assert "(not the committed set)" not in page
    kept["set_hash"] = "0" * 64  # a set re-frozen since the run
    (tmp_path / "cubes-dev-front.json").write_text(json.dumps(kept))
    (row,) = [
        ln
        for ln in results.render(tmp_path, names=["cubes"]).splitlines()
        if ln.startswith("| cubes-dev-front |")
    ]
    assert "00000000 (not the committed set)" in row


def test_a_run_that_writes_no_summary_is_named_and_the_others_still_run(monkeypatch, capsys):
    bad = [results.Run("x-1", ("no-such-domain",)), results.Run("x-2", ("no-such-domain-2",))]
    monkeypatch.setattr(results, "runs", lambda names=None: bad)
    assert results.main(["run"]) == 1  # the real `rivet eval`, refusing each domain (exit 2)
    err = capsys.readouterr().err
    assert "[2/2] rivet eval no-such-domain-2" in err
    assert "2 of 2 runs wrote no summary: x-1, x-2" in err
    assert not (results.RUN_FILES / "x-1.json").exists()
