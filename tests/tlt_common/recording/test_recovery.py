"""A recording cut anywhere keeps every message of the chunks flushed before the cut."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.exceptions import McapError
from mcap.reader import make_reader
from rclpy.serialization import serialize_message
from std_msgs.msg import String

from tlt_common.recording.mcap_writer import McapRecordingWriter
from tlt_common.recording.message_definitions import MessageDefinitionSource
from tlt_common.recording.qos_profiles import offered_qos_yaml, subscription_qos
from tlt_common.recording.reading import read_messages
from tlt_common.recording.recovery import ScanResult, iter_flushed_messages, main, recover

FLUSH_EVERY = 4
TOTAL = 20


def cut_recording(path: Path, compression: str) -> list[int]:
    """Write TOTAL messages, flushing every FLUSH_EVERY, without closing the file (as a killed
    recorder leaves it). Returns the file size after each flush."""
    writer = McapRecordingWriter(path, compression=compression)
    channel = writer.add_channel(
        "/t",
        "std_msgs/msg/String",
        MessageDefinitionSource().full_text("std_msgs/msg/String"),
        offered_qos_yaml([subscription_qos([])]),
    )
    sizes = []
    for i in range(TOTAL):
        writer.write(channel, serialize_message(String(data=str(i))), i, i)
        if (i + 1) % FLUSH_EVERY == 0:
            writer.flush()
            sizes.append(path.stat().st_size)
    return sizes


@pytest.mark.parametrize("compression", ["zstd", "none"])
def test_a_cut_at_any_byte_keeps_the_chunks_before_it(tmp_path: Path, compression: str):
    full = tmp_path / "full.mcap"
    sizes = cut_recording(full, compression)
    data = full.read_bytes()
    assert len(data) == sizes[-1]
    step = max(1, len(data) // 300)
    previous = 0
    for cut in range(sizes[0] - 40, len(data) + 1, step):
        part = tmp_path / "part.mcap"
        part.write_bytes(data[:cut])
        result = ScanResult()
        got = [m.data for _, _, m in iter_flushed_messages(part, result)]
        flushed = sum(1 for s in sizes if s <= cut) * FLUSH_EVERY
        # Everything flushed before the cut survives; a chunk cut inside is lost whole, one
        # complete before its message index records were cut keeps its messages.
        assert flushed <= len(got) <= flushed + FLUSH_EVERY, cut
        assert len(got) % FLUSH_EVERY == 0 and len(got) >= previous, cut
        assert got == [serialize_message(String(data=str(i))) for i in range(len(got))]
        assert not result.complete
        previous = len(got)
    assert previous == TOTAL


def test_recover_writes_a_complete_file_that_standard_readers_open(tmp_path: Path):
    cut = tmp_path / "cut.mcap"
    cut_recording(cut, "zstd")
    with open(cut, "rb") as stream, pytest.raises(McapError):  # no footer: the seeking reader fails
        make_reader(stream).get_summary()
    report = recover(cut, tmp_path / "fixed.mcap")
    assert report.messages == TOTAL and report.channels == 1 and not report.complete
    decoded = list(read_messages(tmp_path / "fixed.mcap"))
    assert [m.decoded_message.data for m in decoded] == [str(i) for i in range(TOTAL)]
    with open(tmp_path / "fixed.mcap", "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_summary().statistics.message_count == TOTAL
        assert "tlt_recording" in {m.name for m in reader.iter_metadata()}
    channel = decoded[0].channel
    assert "offered_qos_profiles" in channel.metadata


def test_a_complete_file_is_reported_complete(tmp_path: Path):
    writer = McapRecordingWriter(tmp_path / "ok.mcap", compression="none")
    writer.close()
    report = recover(tmp_path / "ok.mcap", tmp_path / "copy.mcap")
    assert report.complete and report.messages == 0


def test_cli_reports_counts_and_refuses_non_mcap_input(tmp_path: Path, capsys):
    cut = tmp_path / "cut.mcap"
    cut_recording(cut, "none")
    assert main([str(cut), str(tmp_path / "out.mcap")]) == 0
    assert f"{TOTAL} messages on 1 channels" in capsys.readouterr().out
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    assert main([str(junk), str(tmp_path / "out2.mcap")]) == 2
    assert "not an MCAP file" in capsys.readouterr().err
    assert not (tmp_path / "out2.mcap").exists()
    assert not (tmp_path / "out2.mcap.partial").exists()
    assert main([str(cut), str(cut)]) == 2
    assert main([str(tmp_path / "missing.mcap"), str(tmp_path / "o.mcap")]) == 2
