"""Read a recording back in Python, decoded, with the standard ``mcap`` + ``mcap-ros2-support`` readers.

``mcap.reader.make_reader(stream, decoder_factories=[mcap_ros2.decoder.DecoderFactory()])`` and its
``iter_decoded_messages()`` (or the older ``mcap_ros2.reader.read_ros2_messages``) decode every
channel of a recording except those whose type name the message-definition parser rejects: it
accepts only ``Name`` plus one of the suffixes ``_Request``, ``_Response``, ``_Goal``, ``_Result``,
``_Feedback``, so the type of an action's feedback topic (``pkg/action/X_FeedbackMessage``) and of
a service-introspection topic (``pkg/srv/X_Event``) make it raise as soon as it meets them.
:func:`read_messages` is the same reader with a decoder factory that hands the parser such a
schema under a name it accepts (the definition text, and so the decoding, are unchanged), so whole
recordings decode.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from mcap.reader import DecodedMessageTuple, make_reader
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory

_PARSER_ACCEPTS = re.compile(r"^[A-Z][A-Za-z0-9]*(_(Request|Response|Goal|Result|Feedback))?$")


def parser_safe_name(type_name: str) -> str:
    """``pkg/action/X_FeedbackMessage`` -> ``pkg/action/XFeedbackMessage``; others unchanged."""
    head, _, name = type_name.rpartition("/")
    if _PARSER_ACCEPTS.match(name):
        return type_name
    return f"{head}/{name.replace('_', '')}" if head else name.replace("_", "")


class LenientRos2DecoderFactory(DecoderFactory):
    """``mcap_ros2``'s decoder factory, also for action-feedback and service-event types."""

    def decoder_for(self, message_encoding: str, schema: Schema | None) -> Callable[[bytes], Any] | None:
        if schema is not None:
            safe = parser_safe_name(schema.name)
            if safe != schema.name:
                schema = Schema(id=schema.id, name=safe, encoding=schema.encoding, data=schema.data)
        return super().decoder_for(message_encoding, schema)


def read_messages(
    path: str | Path, topics: Iterable[str] | None = None, log_time_order: bool = True
) -> Iterator[DecodedMessageTuple]:
    """``(schema, channel, message, decoded_message)`` for each message of a complete recording,
    in log-time order (or file order); ``message`` has ``log_time``, ``publish_time``,
    ``sequence`` and the raw ``data``."""
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[LenientRos2DecoderFactory()])
        yield from reader.iter_decoded_messages(
            topics=None if topics is None else list(topics), log_time_order=log_time_order
        )
