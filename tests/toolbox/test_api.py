"""The public surface: re-exports, docstrings, and the prompt documentation."""

from __future__ import annotations

import importlib
import inspect

import pytest

import toolbox
from rivet.cli import main
from toolbox.docs import MODULES, toolbox_docs


def public_objects():
    for name in MODULES:
        module = importlib.import_module(f"toolbox.{name}")
        for attr in module.__all__:
            yield name, attr, getattr(module, attr)


def test_package_reexports_every_public_name_of_every_module():
    exported = set(toolbox.__all__)
    for module, attr, obj in public_objects():
        assert attr in exported, f"toolbox.{module}.{attr} is not re-exported by toolbox"
        assert getattr(toolbox, attr) is obj
    for attr in toolbox.__all__:
        assert hasattr(toolbox, attr)


@pytest.mark.parametrize(
    ("module", "attr", "obj"),
    list(public_objects()),
    ids=[f"{m}.{a}" for m, a, _ in public_objects()],
)
def test_every_public_name_is_documented(module, attr, obj):
    doc = inspect.getdoc(obj)
    assert doc and len(doc) > 20, f"toolbox.{module}.{attr} needs a docstring for the prompt"


def test_docs_list_every_public_name_and_are_deterministic():
    text = toolbox_docs()
    assert text == toolbox_docs()
    assert " at 0x" not in text  # no memory addresses in signatures
    for module, attr, _ in public_objects():
        assert f"## toolbox.{module}" in text
        assert f"`{attr}" in text, attr
    assert (
        len(text) < 56_000
    )  # a prompt section (~14k tokens, the pose refiner included), not a manual


def test_docs_can_be_restricted_to_modules():
    text = toolbox_docs(["render", "geometry"])
    assert "## toolbox.render" in text and "## toolbox.geometry" in text
    assert "## toolbox.search" not in text
    assert text.index("## toolbox.geometry") < text.index("## toolbox.render")


def test_cli_prints_the_docs(capsys):
    assert main(["toolbox", "docs", "--module", "search"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("# toolbox") and "### `astar(" in out


def test_cli_rejects_an_unknown_module(capsys):
    assert main(["toolbox", "docs", "--module", "nope"]) == 2
    assert "known: geometry" in capsys.readouterr().err
