"""The file side alone: what the writer puts in an MCAP file, read back by the standard readers."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import NonSeekingReader, make_reader
from rclpy.serialization import serialize_message
from std_msgs.msg import String

from tlt_common.recording.mcap_writer import McapRecordingWriter, available_compressions
from tlt_common.recording.message_definitions import MessageDefinitionSource
from tlt_common.recording.qos_profiles import offered_qos_yaml, subscription_qos
from tlt_common.recording.reading import read_messages

SOURCE = MessageDefinitionSource()


def write_strings(path: Path, count: int, compression: str, flush_every: int = 0) -> None:
    writer = McapRecordingWriter(path, compression=compression, metadata={"run": "unit"})
    qos = offered_qos_yaml([subscription_qos([])])
    chan_a = writer.add_channel(
        "/a", "std_msgs/msg/String", SOURCE.full_text("std_msgs/msg/String"), qos, "RIHS01_abc"
    )
    chan_b = writer.add_channel("/b", "std_msgs/msg/String", SOURCE.full_text("std_msgs/msg/String"), qos)
    for i in range(count):
        channel = chan_a if i % 2 == 0 else chan_b
        writer.write(channel, serialize_message(String(data=f"m{i}")), 1_000 + i, 500 + i)
        if flush_every and (i + 1) % flush_every == 0:
            writer.flush()
    writer.close()
    writer.close()  # a second close is harmless


@pytest.mark.parametrize("compression", available_compressions())
def test_messages_schema_channels_and_summary_read_back(tmp_path: Path, compression: str):
    path = tmp_path / "r.mcap"
    write_strings(path, 10, compression)
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        header = reader.get_header()
        summary = reader.get_summary()
    assert header.profile == "ros2"
    assert header.library.startswith("tlt-record")
    assert summary is not None
    assert summary.statistics.message_count == 10
    assert summary.statistics.channel_message_counts == {1: 5, 2: 5}
    assert [s.name for s in summary.schemas.values()] == ["std_msgs/msg/String"]  # shared
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
    channels = {c.topic: c for c in summary.channels.values()}
    assert {c.message_encoding for c in channels.values()} == {"cdr"}
    assert channels["/a"].metadata["topic_type_hash"] == "RIHS01_abc"
    assert "topic_type_hash" not in channels["/b"].metadata
    assert "reliability: best_effort" in channels["/a"].metadata["offered_qos_profiles"]
    expected_chunk = "" if compression == "none" else compression
    assert {c.compression for c in summary.chunk_indexes} == {expected_chunk}

    decoded = list(read_messages(path))
    assert [m.decoded_message.data for m in decoded] == [f"m{i}" for i in range(10)]
    assert [m.message.log_time for m in decoded] == [1_000 + i for i in range(10)]
    assert [m.message.publish_time for m in decoded] == [500 + i for i in range(10)]
    assert [m.message.sequence for m in decoded if m.channel.topic == "/a"] == [1, 2, 3, 4, 5]


def test_crcs_of_chunks_and_data_section_validate(tmp_path: Path):
    path = tmp_path / "r.mcap"
    write_strings(path, 50, available_compressions()[0], flush_every=7)
    with open(path, "rb") as stream:
        messages = list(NonSeekingReader(stream, validate_crcs=True).iter_messages())
    assert len(messages) == 50
    with open(path, "rb") as stream:
        assert len(make_reader(stream).get_summary().chunk_indexes) == 8  # 7 flushes + the rest


def test_metadata_record_describes_the_run(tmp_path: Path):
    path = tmp_path / "r.mcap"
    write_strings(path, 1, "none")
    with open(path, "rb") as stream:
        metadata = {m.name: m.metadata for m in make_reader(stream).iter_metadata()}
    assert metadata["tlt_recording"]["run"] == "unit"
    assert metadata["tlt_recording"]["compression"] == "none"
    assert int(metadata["tlt_recording"]["started_unix_ns"]) > 0


def test_unknown_compression_is_refused_before_creating_the_file(tmp_path: Path):
    with pytest.raises(ValueError, match="compression 'brotli' not available"):
        McapRecordingWriter(tmp_path / "x.mcap", compression="brotli")
    assert not (tmp_path / "x.mcap").exists()


def test_parent_directories_are_created(tmp_path: Path):
    path = tmp_path / "run" / "deep" / "r.mcap"
    write_strings(path, 2, "none")
    assert len(list(read_messages(path))) == 2
