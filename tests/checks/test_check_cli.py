"""`rivet check`: exit 0 on pass, 1 on fail, 2 on bad input; prints the report."""

from __future__ import annotations

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
