"""Definitions built from the installed interface files decode the bytes rclpy really serializes."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.records import Schema
from rclpy.serialization import serialize_message

from tlt_common.recording.message_definitions import (
    SEPARATOR,
    DefinitionNotFound,
    MessageDefinitionSource,
    dependencies,
    field_base_type,
    first_field_is_header,
    split_type_name,
)
from tlt_common.recording.reading import LenientRos2DecoderFactory

SOURCE = MessageDefinitionSource()


def decode(type_name: str, data: bytes):
    schema = Schema(id=1, name=type_name, encoding="ros2msg", data=SOURCE.full_text(type_name).encode())
    decoder = LenientRos2DecoderFactory().decoder_for("cdr", schema)
    assert decoder is not None
    return decoder(data)


def test_field_lines_name_their_complex_types_only():
    assert field_base_type("std_msgs/Header header") == "std_msgs/Header"
    assert field_base_type("GoalStatus[] status_list  # comment") == "GoalStatus"
    assert field_base_type("geometry_msgs/Point[<=4] corners") == "geometry_msgs/Point"
    assert field_base_type("string<=10 name") is None
    assert field_base_type("float64[4] values") is None
    assert field_base_type("uint8 KIND_VERTICAL = 1") is None
    assert field_base_type('string GREETING="a # b"') is None
    assert field_base_type("# only a comment") is None
    assert field_base_type("   ") is None


def test_dependencies_resolve_the_package_of_unqualified_types_in_order():
    text = "Foo a\nstd_msgs/msg/Header h\nuint8 X = 1\nFoo[] again\nint32 n\n"
    assert dependencies(text, "pkg") == ["pkg/Foo", "std_msgs/Header"]


def test_first_field_header_skips_comments_and_constants():
    assert first_field_is_header("# about\nuint8 A = 1\nstd_msgs/Header header\nint32 x\n")
    assert not first_field_is_header("int32 x\nstd_msgs/Header header\n")
    assert first_field_is_header(SOURCE.own_text("sensor_msgs/msg/JointState"))
    assert not first_field_is_header(SOURCE.own_text("std_msgs/msg/String"))


def test_type_names_split_with_or_without_the_kind():
    assert split_type_name("std_msgs/msg/String") == ("std_msgs", "msg", "String")
    assert split_type_name("std_msgs/String") == ("std_msgs", "msg", "String")
    with pytest.raises(DefinitionNotFound, match="not a ROS type name"):
        split_type_name("String")


def test_full_text_lists_each_dependency_once_in_the_rosbag2_layout():
    text = SOURCE.full_text("tlt_interfaces/msg/LifterState")
    sections = text.split(SEPARATOR + "\n")
    assert sections[0].startswith("# Telemetry of the lifter firmware")
    assert [s.splitlines()[0] for s in sections[1:]] == [
        "MSG: std_msgs/Header",
        "MSG: builtin_interfaces/Time",
    ]
    goal_status = SOURCE.full_text("action_msgs/msg/GoalStatusArray")
    assert goal_status.count("MSG: unique_identifier_msgs/UUID") == 1
    assert goal_status.count("MSG: builtin_interfaces/Time") == 1


def test_lifter_state_decodes_from_real_cdr():
    from tlt_interfaces.msg import LifterState

    msg = LifterState()
    msg.header.stamp.sec = 12
    msg.header.frame_id = "lifter"
    msg.state = LifterState.STATE_CRS_CONTROL
    msg.encoder_counts = [1, -2, 3, 4]
    msg.limit_switches = [True, False, False, False, False, False, False, True]
    msg.fault = "none"
    decoded = decode("tlt_interfaces/msg/LifterState", serialize_message(msg))
    assert decoded.header.stamp.sec == 12
    assert decoded.header.frame_id == "lifter"
    assert decoded.state == 2
    assert list(decoded.encoder_counts) == [1, -2, 3, 4]
    assert list(decoded.limit_switches) == [True] + [False] * 6 + [True]
    assert decoded.fault == "none"


def test_action_feedback_message_is_cut_from_the_action_file_and_decodes():
    from tlt_interfaces.action import AddMember

    text = SOURCE.full_text("tlt_interfaces/action/AddMember_FeedbackMessage")
    assert text.startswith("unique_identifier_msgs/UUID goal_id\nAddMember_Feedback feedback\n")
    assert "MSG: tlt_interfaces/AddMember_Feedback\nstring step\nfloat32 progress" in text
    msg = AddMember.Impl.FeedbackMessage()
    msg.goal_id.uuid[0] = 9
    msg.feedback.step = "grab strut"
    msg.feedback.progress = 0.25
    decoded = decode("tlt_interfaces/action/AddMember_FeedbackMessage", serialize_message(msg))
    assert decoded.goal_id.uuid[0] == 9
    assert decoded.feedback.step == "grab strut"
    assert decoded.feedback.progress == pytest.approx(0.25)


def test_action_parts_and_service_parts_come_from_their_sections():
    goal = SOURCE.own_text("tlt_interfaces/action/AddMember_Goal")
    assert "string member_id" in goal and "---" not in goal and "parts_discarded" not in goal
    assert SOURCE.own_text("tlt_interfaces/action/AddMember_Result").startswith("bool success")
    response = SOURCE.own_text("tlt_interfaces/srv/SetLifterMode_Response")
    assert "bool success" in response and "uint8 mode" not in response


def test_service_event_decodes():
    from tlt_interfaces.srv import SetLifterMode

    event = SetLifterMode.Event()
    event.info.event_type = 1
    event.request = [SetLifterMode.Request(mode=3)]
    decoded = decode("tlt_interfaces/srv/SetLifterMode_Event", serialize_message(event))
    assert decoded.info.event_type == 1
    assert [r.mode for r in decoded.request] == [3]
    assert list(decoded.response) == []


def test_unknown_types_raise_naming_the_type_and_the_search_path(tmp_path: Path):
    source = MessageDefinitionSource([tmp_path])
    with pytest.raises(DefinitionNotFound, match=f"std_msgs/msg/String under {tmp_path}"):
        source.full_text("std_msgs/msg/String")
    (tmp_path / "pkg" / "msg").mkdir(parents=True)
    (tmp_path / "pkg" / "msg" / "Outer.msg").write_text("Missing inner\n")
    with pytest.raises(DefinitionNotFound, match="pkg/Missing"):
        source.full_text("pkg/msg/Outer")
