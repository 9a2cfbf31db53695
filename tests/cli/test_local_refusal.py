"""`--sandbox local` refuses to run while a model credential is in the environment.

The local backend isolates nothing: a draft runs as the user and can read the environment of
the rivet process and of every process it starts (`rivet eval --workers 2` starts several), so
the one promise it used to make — that the key stays unreadable — did not hold. Every command
with a `--sandbox` option now refuses `local` (exit 2, saying why) while any credential the
model clients read is set, and the list of those credentials is held to what the clients read.
"""

from __future__ import annotations

import ast
import contextlib
import io
from pathlib import Path

import pytest

from rivet.cli import main
from rivet.commands._options import CREDENTIAL_VARIABLES

REPO = Path(__file__).resolve().parents[2]

# One command line per command that runs drafts or programs (each would start the local
# backend); none gets as far as starting it.
COMMANDS = {
    "check": ["check", "cubes", "relate", "missing.py"],
    "eval": ["eval", "cubes", "--workers", "2"],
    "solve": ["solve", "cubes", "start_dir", "goal_dir"],
    "author": ["author", "cubes"],
    "sandbox run": ["sandbox", "run", "missing.py", "--function", "f"],
    "transcript pack": ["transcript", "pack", "cubes", "somewhere"],
    "refreeze": ["refreeze", "cubes"],
}


def _run(argv: list[str]) -> tuple[int, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as e:
            code = int(e.code or 0)
    return code, out.getvalue() + err.getvalue()


def _commands_with_sandbox_option() -> set[str]:
    from rivet.cli import build_parser

    found = set()
    parser = build_parser()
    (sub,) = [a for a in parser._actions if a.dest == "command"]
    for name, p in sub.choices.items():
        stack = [(name, p)]
        while stack:
            label, q = stack.pop()
            for a in q._actions:
                if "--sandbox" in a.option_strings:
                    found.add(label)
                if a.choices and isinstance(a.choices, dict):
                    stack += [(f"{label} {k}", v) for k, v in a.choices.items()]
    return found


def test_every_command_with_a_sandbox_option_is_covered():
    assert _commands_with_sandbox_option() == set(COMMANDS)


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize("variable", CREDENTIAL_VARIABLES)
def test_local_refuses_with_a_credential(monkeypatch, command, variable):
    for name in CREDENTIAL_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv(variable, "sk-test-not-a-real-key")
    code, text = _run([*COMMANDS[command], "--sandbox", "local"])
    assert code == 2, text
    assert f"--sandbox local refuses to run while {variable} is set" in text, text
    assert "sk-test-not-a-real-key" not in text  # the value is never printed
    assert "Traceback" not in text


def test_every_credential_set_is_named(monkeypatch):
    for name in CREDENTIAL_VARIABLES:
        monkeypatch.setenv(name, "x")
    code, text = _run([*COMMANDS["eval"], "--sandbox", "local"])
    assert code == 2
    assert all(name in text for name in CREDENTIAL_VARIABLES), text


def test_an_empty_variable_is_not_a_credential(monkeypatch):
    """Parsing gets past the option (the command then fails on its missing file: exit 2 for
    that reason, not the refusal)."""
    for name in CREDENTIAL_VARIABLES:
        monkeypatch.setenv(name, "")
    code, text = _run([*COMMANDS["sandbox run"], "--sandbox", "local"])
    assert "refuses to run" not in text
    assert code == 2 and "missing.py" in text, text


def test_docker_is_not_refused(monkeypatch):
    monkeypatch.setenv("ANTHROPIC_API_KEY", "x")
    code, text = _run([*COMMANDS["sandbox run"], "--sandbox", "docker"])
    assert "refuses to run" not in text
    assert code == 2 and "missing.py" in text, text


def _variables_read(path: Path) -> set[str]:
    """Every environment variable a module reads by a literal name (os.environ.get / pop / [],
    os.getenv)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.args:
            reader = f"{ast.unparse(node.func.value)}.{node.func.attr}"
            key = node.args[0]
            if reader in ("os.environ.get", "os.environ.pop", "os.getenv") and (
                isinstance(key, ast.Constant) and isinstance(key.value, str)
            ):
                names.add(key.value)
        elif (
            isinstance(node, ast.Subscript)
            and ast.unparse(node.value) == "os.environ"
            and isinstance(node.slice, ast.Constant)
            and isinstance(node.slice.value, str)
        ):
            names.add(node.slice.value)
    return names


def test_the_list_holds_every_credential_the_clients_read():
    read = set()
    for path in (REPO / "agent" / "clients").glob("*.py"):
        read |= _variables_read(path)
    secrets = {n for n in read if n.endswith(("_KEY", "_TOKEN", "_SECRET"))}
    assert secrets, "no credential found: the scan is broken"
    assert secrets <= set(CREDENTIAL_VARIABLES), secrets - set(CREDENTIAL_VARIABLES)
