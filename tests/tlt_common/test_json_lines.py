"""JSON-lines records: read while they are written, by kind."""

from __future__ import annotations

from tlt_common import json_lines
from tlt_common.json_lines import JsonLinesWriter


def test_entries_come_back_in_order_and_by_kind(tmp_path):
    record = JsonLinesWriter(tmp_path / "record.jsonl")
    record.append({"kind": "ready"})
    record.append({"kind": "request", "member": "S1"})
    record.append({"kind": "request", "member": "S2"})

    assert json_lines.read(record.path, "request") == [
        {"kind": "request", "member": "S1"},
        {"kind": "request", "member": "S2"},
    ]
    assert len(json_lines.read(record.path)) == 3
    assert json_lines.read(record.path, "clock_started") == []


def test_a_file_not_there_yet_reads_empty(tmp_path):
    assert json_lines.read(tmp_path / "not_yet.jsonl") == []


def test_a_line_half_written_is_left_out_and_the_rest_kept(tmp_path):
    path = tmp_path / "record.jsonl"
    path.write_text('{"member": "S1"}\n{"member": "S2"}\n{"memb')

    assert json_lines.read(path) == [{"member": "S1"}, {"member": "S2"}]


def test_entries_without_a_kind_are_not_taken_for_one(tmp_path):
    path = tmp_path / "placements.jsonl"
    path.write_text('{"member": "S1"}\n')

    assert json_lines.read(path, "request") == []
    assert json_lines.read(path) == [{"member": "S1"}]
