"""`rivet check`: exit 0 on pass, 1 on fail, 2 on bad input; prints the report."""

from __future__ import annotations

import json

import pytest

from rivet.cli import main

from .conftest import PROGRAMS


def test_passing_draft_exits_0(capsys, tmp_path):
    code = main(
        [
            "check",
            "cubes",
            "relate",
            str(PROGRAMS / "relate.py"),
            "--sandbox",
            "local",
            "--out",
            str(tmp_path),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    assert "ok   property.translation_invariant" in out and "passed all" in out


def test_failing_draft_exits_1_and_prints_the_first_failure(capsys, tmp_path):
    code = main(
        [
            "check",
            "cubes",
            "plan",
            str(PROGRAMS / "drafts" / "plan_v1.py"),
            "--sandbox",
            "local",
            "--deps",
            str(PROGRAMS),
            "--out",
            str(tmp_path),
        ]
    )
    out = capsys.readouterr().out
    assert code == 1
    assert "FAIL property.reaches_goal" in out
    assert "### First failure: `property.reaches_goal`" in out


def test_only_runs_the_checks_asked_for(capsys, tmp_path):
    """plan_v1 fails reaches_goal; asked for another check alone it passes, the rest unrun."""
    argv = ["check", "cubes", "plan", str(PROGRAMS / "drafts" / "plan_v1.py"), "--sandbox",
            "local", "--deps", str(PROGRAMS), "--out", str(tmp_path), "--seed", "5"]  # fmt: skip
    assert main([*argv, "--only", "property.deterministic"]) == 0
    out = capsys.readouterr().out
    assert "ok   property.deterministic" in out and "ok   schema.output" in out
    assert "skip property.reaches_goal" in out and "skip domain.cubes.temporary_places_clear" in out
    assert "(--only: 6 other checks not run)" in out
    assert main([*argv, "--only", "property.reaches_goal", "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    ran = {c["name"]: c["status"] for c in report["checks"] if c["status"] != "skipped"}
    assert ran.pop("property.reaches_goal") == "failed"
    assert all(n.startswith(("interface.", "schema.")) for n in ran), ran


def test_only_names_a_check_of_the_function(capsys):
    argv = ["check", "cubes", "relate", str(PROGRAMS / "relate.py"), "--sandbox", "local"]
    assert main([*argv, "--only", "property.reaches_goal"]) == 2
    err = capsys.readouterr().err
    assert "no relate check is named property.reaches_goal" in err
    assert "property.translation_invariant" in err  # the checks it has are listed
    assert main(["check", "cubes", "--system", str(PROGRAMS), "--only", "schema.output"]) == 2


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["check", "cube", "plan", "x.py"], "unknown domain 'cube'"),
        (
            ["check", "cubes", "plan", "/nonexistent/draft.py", "--sandbox", "local"],
            "cannot read draft",
        ),
    ],
)
def test_bad_input_exits_2(capsys, argv, message):
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_unknown_function_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as e:
        main(["check", "cubes", "planner", "x.py"])
    assert e.value.code == 2


def test_package_exports_resolve():
    import checks

    for name in checks.__all__:
        assert hasattr(checks, name), name
