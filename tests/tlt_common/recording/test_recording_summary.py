"""``tlt record info``: per-topic counts, times and rates of a recording, complete or cut short."""

from __future__ import annotations

from pathlib import Path

import pytest
from std_msgs.msg import Int32, String

from tlt_common.cli import main as tlt
from tlt_common.recording.record_command import main
from tlt_common.recording.summary import NS_PER_S, summarise

T0 = 1_765_000_000 * NS_PER_S  # wall-time log times


def entries() -> list:
    out = [("/a", "std_msgs/msg/String", String(data=f"a{i}"), T0 + i * NS_PER_S // 10) for i in range(5)]
    out += [("/b", "std_msgs/msg/Int32", Int32(data=i), T0 + NS_PER_S + i * NS_PER_S) for i in range(3)]
    return sorted(out, key=lambda e: e[3])


def test_counts_times_rates_and_duration(make_recording):
    summary = summarise(make_recording(entries()))
    assert summary.complete and summary.stopped_at == ""
    assert summary.message_count == 8
    a, b = summary.topics["/a"], summary.topics["/b"]
    assert (a.type_name, a.count, a.first_ns, a.last_ns) == (
        "std_msgs/msg/String",
        5,
        T0,
        T0 + 4 * NS_PER_S // 10,
    )
    assert (b.type_name, b.count, b.first_ns, b.last_ns) == (
        "std_msgs/msg/Int32",
        3,
        T0 + NS_PER_S,
        T0 + 3 * NS_PER_S,
    )
    assert a.rate_hz == pytest.approx(10.0)
    assert b.rate_hz == pytest.approx(1.0)
    assert summary.start_ns == T0 and summary.end_ns == T0 + 3 * NS_PER_S
    assert summary.duration_s == pytest.approx(3.0)
    assert summary.metadata["tlt_recording"]["compression"] == "none"


def test_a_single_message_has_no_rate(make_recording):
    summary = summarise(make_recording([("/a", "std_msgs/msg/String", String(data="x"), 7)]))
    assert summary.topics["/a"].rate_hz is None
    assert summary.duration_s == 0.0


def test_info_prints_the_table(make_recording, capsys):
    path = make_recording(entries())
    assert tlt(["record", "info", str(path)]) == 0  # through the tlt command
    out = capsys.readouterr().out
    assert f"file:      {path} (complete)" in out
    assert "duration:  3.000 s" in out
    assert "messages:  8 on 2 topics" in out
    assert "2025-12-06 05:46:40.000 UTC" in out  # T0 as a date: wall-time log times
    rows = {line.split()[0]: line.split() for line in out.splitlines() if line.startswith("/")}
    assert rows["/a"] == ["/a", "std_msgs/msg/String", "5", "0.000", "0.400", "10.00"]
    assert rows["/b"] == ["/b", "std_msgs/msg/Int32", "3", "1.000", "3.000", "1.00"]


def test_sim_time_log_times_are_not_shown_as_dates(make_recording, capsys):
    path = make_recording([("/a", "std_msgs/msg/String", String(data="x"), 12 * NS_PER_S + 5)])
    assert main(["info", str(path)]) == 0
    assert "start:     12.000000005 s (sim time)" in capsys.readouterr().out


def test_a_cut_recording_is_summarised_up_to_the_cut(make_recording, capsys):
    path = make_recording(entries(), flush_every=3, close=False)  # 6 of 8 messages flushed
    summary = summarise(path)
    assert not summary.complete
    assert summary.message_count == 6
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "CUT SHORT" in out and "tlt-mcap-recover" in out
    assert "messages:  6 on 2 topics" in out


@pytest.mark.parametrize(
    "content", [None, b"", b"not an mcap file at all\n"], ids=["missing", "empty", "text"]
)
def test_a_missing_or_foreign_file_is_exit_2_naming_it(tmp_path: Path, capsys, content):
    path = tmp_path / "x.mcap"
    if content is not None:
        path.write_bytes(content)
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"tlt record info: cannot read {path}: ")
    assert ("No such file" in err) if content is None else ("not an MCAP file" in err)
