"""What a manifest records of the code its set relies on changes when that code's behaviour can
(docs/design.md, "Artifacts"): a comment, a private docstring or a re-formatting does not
change it; a changed constant, a changed schema value or a changed public docstring (the
documentation the prompt shows) does."""

from __future__ import annotations

import json
from pathlib import Path

from artifacts.hashing import REPO, behaviour_bytes


def _edited(tmp_path: Path, source: Path, edit) -> Path:
    out = tmp_path / source.name
    out.write_text(edit(source.read_text()))
    return out


def test_a_comment_or_a_docstring_leaves_a_module_unchanged(tmp_path):
    for rel in ("geometry/grasps.py", "toolbox/render.py"):
        path = REPO / rel
        before = behaviour_bytes(path)

        def commented(text):
            return "# a maintainer's note\n" + text.replace("\n\n\n", "\n\n\n# between\n", 1)

        assert behaviour_bytes(_edited(tmp_path, path, commented)) == before, rel

        def reformatted(text):
            return text.replace("\n\n\n", "\n\n\n\n", 3)

        assert behaviour_bytes(_edited(tmp_path, path, reformatted)) == before, rel


def test_docstrings_are_dropped_but_code_is_not(tmp_path):
    a = tmp_path / "a.py"
    a.write_text('"""Module."""\n\n\ndef f(x):\n    """Doc."""\n    return x + 1\n')
    b = tmp_path / "b.py"
    b.write_text('"""Other words."""\n\n\ndef f(x):\n    """More."""\n    return x + 1\n')
    c = tmp_path / "c.py"
    c.write_text('"""Module."""\n\n\ndef f(x):\n    """Doc."""\n    return x + 2\n')
    d = tmp_path / "d.py"
    d.write_text("def f(x):\n    return x + 1\n")
    assert behaviour_bytes(a) == behaviour_bytes(b) == behaviour_bytes(d)
    assert behaviour_bytes(a) != behaviour_bytes(c)


def test_a_json_file_by_its_values(tmp_path):
    a, b, c = (tmp_path / f"{n}.json" for n in "abc")
    a.write_text(json.dumps({"x": 1, "y": [1, 2]}))
    b.write_text(json.dumps({"y": [1, 2], "x": 1}, indent=4))
    c.write_text(json.dumps({"x": 1, "y": [1, 3]}))
    assert behaviour_bytes(a) == behaviour_bytes(b) != behaviour_bytes(c)


def test_the_toolbox_hash_follows_the_documentation_the_prompt_shows(monkeypatch):
    import toolbox.docs
    from artifacts.hashing import checked_against

    before = checked_against()
    real = toolbox.docs.toolbox_docs
    monkeypatch.setattr(toolbox.docs, "toolbox_docs", lambda *a: real(*a) + "\nOne more line.")
    after = checked_against()
    assert after["contracts_hash"] == before["contracts_hash"]
    assert after["toolbox_hash"] != before["toolbox_hash"]
