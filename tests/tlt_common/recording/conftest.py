"""Recordings made with the project's own writer, for the tests of reading them back."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pytest
from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message

from tlt_common.recording.mcap_writer import McapRecordingWriter
from tlt_common.recording.message_definitions import MessageDefinitionSource
from tlt_common.recording.qos_profiles import offered_qos_yaml

SOURCE = MessageDefinitionSource()

# (topic, type name, message, log time ns)
Entry = tuple[str, str, Any, int]


def write_recording(
    path: Path,
    entries: Sequence[Entry],
    qos: dict[str, QoSProfile] | None = None,
    flush_every: int = 0,
    close: bool = True,
) -> Path:
    """Write ``entries`` in order; a topic's channel offers ``qos[topic]`` (reliable, depth 10 by
    default). ``close=False`` leaves the file as a killed recorder does (flushed chunks only)."""
    writer = McapRecordingWriter(path, compression="zstd" if flush_every else "none")
    channels: dict[str, int] = {}
    for i, (topic, type_name, msg, log_time) in enumerate(entries, 1):
        if topic not in channels:
            profile = (qos or {}).get(topic, QoSProfile(depth=10))
            channels[topic] = writer.add_channel(
                topic, type_name, SOURCE.full_text(type_name), offered_qos_yaml([profile])
            )
        writer.write(channels[topic], serialize_message(msg), log_time, log_time)
        if flush_every and i % flush_every == 0:
            writer.flush()
    if close:
        writer.close()
    return path


@pytest.fixture
def make_recording(tmp_path: Path) -> Callable[..., Path]:
    """``make_recording(entries, name="r.mcap", **kwargs)``: :func:`write_recording` in tmp_path."""

    def make(entries: Sequence[Entry], name: str = "r.mcap", **kwargs: Any) -> Path:
        return write_recording(tmp_path / name, entries, **kwargs)

    return make
