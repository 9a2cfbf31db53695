"""JSON-lines files survive a kill mid-write: what was appended before holds, a torn line ends it."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st

from artifacts import jsonl

RECORDS = st.lists(
    st.dictionaries(st.text(max_size=5), st.integers() | st.text(max_size=8), max_size=3),
    max_size=6,
)


@given(records=RECORDS, cut=st.floats(0, 1))
def test_a_file_cut_anywhere_reads_back_the_records_written_whole(records, cut):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "log.jsonl"
        path.touch()
        for r in records:
            jsonl.append(path, r)
        assert jsonl.read(path) == records
        data = path.read_bytes()
        path.write_bytes(data[: int(cut * len(data))])
        got = jsonl.read(path)
        assert got == records[: len(got)]  # a prefix, nothing invented
        whole = path.read_bytes().count(b"\n")
        assert len(got) >= whole  # every line that was ended holds


def test_no_file_is_no_records(tmp_path):
    assert jsonl.read(tmp_path / "none.jsonl") == []


def test_sorted_keys_when_asked(tmp_path):
    jsonl.append(tmp_path / "j.jsonl", {"b": 1, "a": 2}, sort_keys=True)
    assert (tmp_path / "j.jsonl").read_text() == json.dumps({"a": 2, "b": 1}) + "\n"
