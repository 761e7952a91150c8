"""``tlt record export``: chosen topics of a recording as CSV, a row per message, fields flattened."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from geometry_msgs.msg import TransformStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from tlt_common.recording.csv_export import csv_name, export_csv
from tlt_common.recording.record_command import main
from tlt_common.recording.summary import NS_PER_S


def read_csv(path: Path) -> list[list[str]]:
    with open(path, newline="", encoding="utf-8") as stream:
        return list(csv.reader(stream))


def joint_state(i: int) -> JointState:
    msg = JointState(name=["lift", "grip"], position=[0.5 * i, -1.25], velocity=[], effort=[])
    msg.header.stamp.sec = 100 + i
    msg.header.stamp.nanosec = 7
    msg.header.frame_id = "base"
    return msg


def tree_status(i: int):
    from tlt_interfaces.msg import TreeStatus

    return TreeStatus(
        agent="crs", shape_hash=0xABCD, tick_count=i, node_count=9, part_count=1, status=[0x1B, 255]
    )


def transforms():
    from tlt_interfaces.msg import TransformArray

    t = TransformStamped(child_frame_id="tower")
    t.header.frame_id = "world"
    t.transform.translation.x = 1.5
    t.transform.rotation.w = 1.0
    return TransformArray(transforms=[t])


def recording(make_recording) -> Path:
    entries = []
    for i in range(3):
        t = 5 * NS_PER_S + i * NS_PER_S // 4 + 3
        entries.append(("/lifter/joints", "sensor_msgs/msg/JointState", joint_state(i), t))
        entries.append(("/chatter", "std_msgs/msg/String", String(data=f'say "{i}",\nnew line'), t + 1))
    entries.append(("/crs/tree_status", "tlt_interfaces/msg/TreeStatus", tree_status(4), 6 * NS_PER_S))
    entries.append(("/twin/truth", "tlt_interfaces/msg/TransformArray", transforms(), 6 * NS_PER_S + 1))
    return make_recording(entries)


def test_rows_columns_and_values(make_recording, tmp_path: Path):
    path = recording(make_recording)
    out = tmp_path / "csv"
    report = export_csv(path, ["/lifter/joints", "/chatter", "/crs/tree_status", "/twin/truth"], out)
    assert report.complete
    assert report.rows == {"/lifter/joints": 3, "/chatter": 3, "/crs/tree_status": 1, "/twin/truth": 1}
    assert sorted(p.name for p in out.iterdir()) == [
        "chatter.csv", "crs.tree_status.csv", "lifter.joints.csv", "twin.truth.csv",
    ]  # fmt: skip

    joints = read_csv(out / "lifter.joints.csv")
    assert joints[0] == [
        "log_time", "header.stamp.sec", "header.stamp.nanosec", "header.frame_id",
        "name", "position", "velocity", "effort",
    ]  # fmt: skip
    assert joints[1:] == [
        [
            f"5.{i * 250_000_000 + 3:09d}",
            str(100 + i),
            "7",
            "base",
            '["lift", "grip"]',
            f"[{0.5 * i}, -1.25]",
            "[]",
            "[]",
        ]
        for i in range(3)
    ]
    chatter = read_csv(out / "chatter.csv")
    assert chatter[0] == ["log_time", "data"]
    assert [row[1] for row in chatter[1:]] == [f'say "{i}",\nnew line' for i in range(3)]

    tree = read_csv(out / "crs.tree_status.csv")
    assert dict(zip(tree[0], tree[1], strict=True)) == {
        "log_time": "6.000000000", "header.stamp.sec": "0", "header.stamp.nanosec": "0",
        "header.frame_id": "",
        "agent": "crs", "shape_hash": str(0xABCD), "tick_count": "4", "node_count": "9", "part_index": "0",
        "part_count": "1", "first_node": "0", "status": "[27, 255]",
    }  # fmt: skip

    truth = read_csv(out / "twin.truth.csv")
    assert truth[0] == ["log_time", "transforms"]
    (transform,) = json.loads(truth[1][1])
    assert transform["header"]["frame_id"] == "world" and transform["child_frame_id"] == "tower"
    assert transform["transform"]["translation"] == {"x": 1.5, "y": 0.0, "z": 0.0}
    assert transform["transform"]["rotation"]["w"] == 1.0


def test_the_command_names_the_files_and_refuses_unknown_topics(make_recording, tmp_path: Path, capsys):
    path = recording(make_recording)
    out = tmp_path / "csv"
    assert main(["export", str(path), "--topics", "/chatter", "--out", str(out)]) == 0
    assert capsys.readouterr().out.strip() == f"{out / 'chatter.csv'}: 3 rows (/chatter)"
    assert main(["export", str(path), "--topics", "/chatter", "/nope", "--out", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err
    assert "has no topic /nope" in err and "/crs/tree_status" in err
    assert not (tmp_path / "none").exists()


def test_a_cut_recording_exports_what_was_flushed(make_recording, tmp_path: Path, capsys):
    entries = [("/c", "std_msgs/msg/String", String(data=str(i)), i) for i in range(10)]
    path = make_recording(entries, flush_every=4, close=False)
    assert main(["export", str(path), "--topics", "/c", "--out", str(tmp_path / "csv")]) == 0
    assert "was cut short" in capsys.readouterr().err
    rows = read_csv(tmp_path / "csv" / "c.csv")
    assert [r[1] for r in rows[1:]] == [str(i) for i in range(8)]


def test_csv_names_keep_topics_apart():
    assert csv_name("/crs/tree_status") == "crs.tree_status.csv"
    assert csv_name("/crs_tree/status") == "crs_tree.status.csv"
