"""The HTML run report shows what drafts produced as escaped text (issue 35, item 5): no markup
of theirs, and invisible or reordering characters (bidi overrides, zero-width) as escapes."""

from __future__ import annotations

import unicodedata

from agent.journal import Journal
from agent.report import write_report

SCRIPT = "<script>alert(1)</script>"
HIDDEN = "\u202e\u2066\u200b\ufeff"


def test_draft_text_is_escaped_in_the_html_report(tmp_path):
    journal = Journal(tmp_path / "run")
    drafts = [
        # a "Trojan Source" comment: the override makes the line read otherwise than it runs
        f"def relate(records, meshes):\n    # {HIDDEN[0]} admin only {HIDDEN[1]}\n    return 1\n",
        f"def relate(records, meshes):\n    return '{SCRIPT}{HIDDEN}'\n",
    ]
    # a report as a file on disk may hold it (written by another version, or edited): it is not
    # trusted to be sanitised already
    report = {
        "schema_version": 1,
        "domain": "cubes",
        "function": "relate",
        "passed": False,
        "first_failure": "schema.output",
        "checks": [
            {
                "name": f"schema.output{SCRIPT}",
                "category": "schema",
                "status": f'failed"><b>{SCRIPT}',
                "message": f"raised ValueError: {SCRIPT} {HIDDEN} & more",
            }
        ],
    }
    for attempt, draft in enumerate(drafts, 1):
        journal.save_draft("relate", attempt, draft)
        journal.save_report("relate", attempt, report, f"# Verdict {SCRIPT}{HIDDEN}")
    html = write_report(journal, "hostile").read_text()
    assert SCRIPT not in html and "<b>" not in html
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html
    assert html.count("\\u202e\\u2066\\u200b\\ufeff") >= 3  # message, feedback, the diff
    assert "\\u202e admin only \\u2066" in html  # the first draft, shown in full
    assert not [c for c in html if unicodedata.category(c) in ("Cf", "Cc") and c not in "\n\t"]
