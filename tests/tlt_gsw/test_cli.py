"""``tlt gsw`` headless commands against a CRS ground link on 127.0.0.1."""

from __future__ import annotations

import csv
import io
import os
import socket
import threading
import time
from pathlib import Path

import pytest
import yaml

from tlt_common.ccsds.auth import KeyRing, write_key_file
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.free_port import free_udp_port
from tlt_crs.ground_link import GroundLink
from tlt_gsw import cli

DEFS = load_definitions()
REPO = Path(__file__).resolve().parents[2]


def _link_yaml(tmp_path: Path, key_file: Path, crs_port: int) -> str:
    config = tmp_path / "link.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                "key_file": str(key_file),
                "key_id": 3,
                "crs": {
                    "bind_host": "127.0.0.1",
                    "bind_port": 0,
                    "replay_state": str(tmp_path / "replay.json"),
                },
                "gsw": {
                    "crs_host": "127.0.0.1",
                    "crs_port": crs_port,
                    "bind_host": "127.0.0.1",
                    "bind_port": 0,
                    "archive": str(tmp_path / "archive.sqlite"),
                    "command_state": str(tmp_path / "seq.json"),
                    "ack_timeout_s": 5.0,
                },
            }
        )
    )
    return str(config)


@pytest.fixture
def setup(tmp_path):
    key_file = write_key_file(tmp_path / "keys" / "ground.key", {3: os.urandom(32)}, {1: os.urandom(32)})
    handled = []
    crs_holder = {}

    def handler(command):
        handled.append(command)
        crs_holder["crs"].complete(command, detail="done")

    crs = GroundLink(
        DEFS, KeyRing.load(key_file), tmp_path / "replay.json", on_command=handler, stats_period_s=0
    )
    crs_holder["crs"] = crs
    crs.start()
    config = tmp_path / "link.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                "key_file": str(key_file),
                "key_id": 3,
                "crs": {
                    "bind_host": "127.0.0.1",
                    "bind_port": 0,
                    "replay_state": str(tmp_path / "replay.json"),
                },
                "gsw": {
                    "crs_host": "127.0.0.1",
                    "crs_port": crs.address[1],
                    "bind_host": "127.0.0.1",
                    "bind_port": 0,
                    "archive": str(tmp_path / "archive.sqlite"),
                    "command_state": str(tmp_path / "seq.json"),
                    "ack_timeout_s": 5.0,
                },
            }
        )
    )
    yield {
        "config": str(config),
        "crs": crs,
        "handled": handled,
        "archive": tmp_path / "archive.sqlite",
        "tmp": tmp_path,
    }
    crs.close()


def run(*argv: str) -> tuple[int, str]:
    out = io.StringIO()
    return cli.main(list(argv), out=out), out.getvalue()


def test_send_waits_for_accepted_and_completed(setup):
    code, text = run("--config", setup["config"], "send", "start", "--wait-complete")
    assert code == cli.EXIT_OK, text
    assert "accepted" in text and "completed (done)" in text
    assert [c.name for c in setup["handled"]] == ["start"]
    code, text = run(
        "--config",
        setup["config"],
        "send",
        "set_blackboard_value",
        "key=speed",
        "value=int:3",
        "--wait-complete",
    )
    assert code == cli.EXIT_OK and "accepted" in text and "completed" in text
    assert setup["handled"][-1].params == {"key": "speed", "value": 3}
    code, text = run("--config", setup["config"], "query", "--counts")
    assert code == 0
    rows = [line.split() for line in text.splitlines()]
    assert ["tx", "start", "ok", "1"] in rows and ["tx", "set_blackboard_value", "ok", "1"] in rows
    assert ["rx", "ack", "ok", "4"] in rows  # accepted and completed for each command


def test_tower_corrections_are_sent_as_set_blackboard_value_and_archived(setup):
    code, text = run(
        "--config", setup["config"], "correct-member", "bay1/vertical/x0_y1", "placed", "--wait-complete"
    )
    assert code == cli.EXIT_OK and "completed (done)" in text, text
    code, text = run(
        "--config", setup["config"], "correct-dispenser", "vertical_dispenser_x", "5", "--wait-complete"
    )
    assert code == cli.EXIT_OK and "completed (done)" in text, text
    assert [(c.name, c.params) for c in setup["handled"]] == [
        ("set_blackboard_value", {"key": "tower/bay1/vertical/x0_y1", "value": "placed"}),
        ("set_blackboard_value", {"key": "dispenser/vertical_dispenser_x", "value": 5}),
    ]
    code, text = run("--config", setup["config"], "query", "--counts")
    rows = [line.split() for line in text.splitlines()]
    assert ["tx", "set_blackboard_value", "ok", "2"] in rows


def test_a_mark_outside_the_models_marks_is_refused_before_sending(setup, capsys):
    with pytest.raises(SystemExit) as exit_:
        run("--config", setup["config"], "correct-member", "bay1/cross_frame", "vanished")
    assert exit_.value.code == cli.EXIT_USAGE and "invalid choice: 'vanished'" in capsys.readouterr().err
    assert setup["handled"] == []


def test_a_correction_the_crs_refuses_prints_the_reason(tmp_path):
    """Against a CRS end that checks corrections with the tower model's rules."""
    from tlt_common.bt.ground_keys import route
    from tlt_common.ccsds.reasons import Reason
    from tlt_common.mission.schema import load_mission
    from tlt_common.mission.tower_model import TowerModel

    model = TowerModel(load_mission(REPO / "missions" / "one_bay.yaml"))

    def validator(command):
        key = route(command.params["key"])
        why = model.check_correction(key.name, command.params["value"])
        return (Reason.REFUSED, why) if why else None

    key_file = write_key_file(tmp_path / "keys" / "ground.key", {3: os.urandom(32)}, {1: os.urandom(32)})
    crs = GroundLink(
        DEFS, KeyRing.load(key_file), tmp_path / "replay.json", validator=validator, stats_period_s=0
    )
    crs.start()
    try:
        config = _link_yaml(tmp_path, key_file, crs.address[1])
        code, text = run("--config", config, "correct-member", "bay1/cross_frame", "unplaced", "--wait-ack")
    finally:
        crs.close()
    assert code == cli.EXIT_REFUSED
    assert "rejected reason=refused ('bay1/cross_frame' is already NOT_PLACED)" in text, text


def test_levers_lists_every_agents_keys_the_corrections_and_the_actuator_table():
    code, text = run("levers")
    assert code == cli.EXIT_OK
    for expected in (
        "lifter_speed",
        "ars_x/settle_s",
        "ars_y/fire_s",
        "tower/<member id>",
        "dispenser/<name>",
    ):
        assert expected in text
    for actuator in DEFS.actuators.values():
        line = next(line for line in text.splitlines() if line.split()[:1] == [actuator.name])
        assert ", ".join(actuator.states) in line


def test_hazardous_command_needs_confirmation(setup, capsys):
    code, _ = run("--config", setup["config"], "send", "stop")
    assert code == cli.EXIT_USAGE and "--yes" in capsys.readouterr().err
    code, text = run("--config", setup["config"], "send", "stop", "--yes", "--wait-ack")
    assert code == cli.EXIT_OK and "accepted" in text


def test_bad_parameters_are_refused_before_sending(setup, capsys):
    code, _ = run(
        "--config", setup["config"], "send", "set_actuator_state", "actuator=lifter", "state=fly", "--yes"
    )
    assert code == cli.EXIT_USAGE and "not a state of lifter" in capsys.readouterr().err
    code, _ = run("--config", setup["config"], "send", "set_blackboard_value", "key=a")
    assert code == cli.EXIT_USAGE and "needs parameter value" in capsys.readouterr().err
    code, _ = run("--config", setup["config"], "send", "launch")
    assert code == cli.EXIT_USAGE and "unknown command" in capsys.readouterr().err
    assert setup["handled"] == []


def test_no_ack_in_time_is_exit_3(setup):
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    try:
        code, text = run(
            "--config",
            setup["config"],
            "send",
            "pause",
            "--wait-ack",
            "--timeout",
            "0.3",
            "--crs",
            f"127.0.0.1:{silent.getsockname()[1]}",
        )
    finally:
        silent.close()
    assert code == cli.EXIT_TIMEOUT and "no acknowledgement within 0.3 s" in text


def test_missing_key_file_is_a_clear_error(setup, capsys):
    code, _ = run("--config", setup["config"], "send", "start", "--key-file", str(setup["tmp"] / "nope"))
    assert code == cli.EXIT_USAGE and "cannot read key file" in capsys.readouterr().err


def test_watch_prints_telemetry_with_limits_and_export_writes_csv(setup):
    port = free_udp_port()
    crs = setup["crs"]
    crs.gsw_address = ("127.0.0.1", port)
    result = {}
    argv = ["--config", setup["config"], "watch", "--bind", f"127.0.0.1:{port}", "--count", "3"]
    argv += ["--duration", "10", "--kind", "hk_lifter"]

    def watch() -> None:
        result["code"], result["text"] = run(*argv)

    watcher = threading.Thread(target=watch)
    watcher.start()
    lifter = {
        "state": "crs_control",
        "position_0": 0.5,
        "position_1": 0.5,
        "position_2": 0.5,
        "position_3": 2.2,
        "velocity": 100,
        "limit_switches": 0,
        "watchdog_tripped": False,
        "link_ok": True,
    }
    deadline = time.monotonic() + 10
    while watcher.is_alive() and time.monotonic() < deadline:
        crs.send_telemetry("hk_lifter", lifter)
        crs.send_event(1, "HELLO", "not shown: filtered out")
        time.sleep(0.05)
    watcher.join(5)
    assert result["code"] == 0
    lines = [line for line in result["text"].splitlines() if " hk_lifter " in line]
    assert len(lines) == 3
    assert (
        "position_3=2.2 m [RED]" in lines[0]
        and "state=crs_control" in lines[0]
        and "HELLO" not in result["text"]
    )
    out_csv = setup["tmp"] / "lifter.csv"
    code, _ = run(
        "--config",
        setup["config"],
        "export",
        "--kind",
        "hk_lifter",
        "--fields",
        "state,position_3",
        "-o",
        str(out_csv),
    )
    assert code == 0
    rows = list(csv.reader(out_csv.open()))
    assert rows[0] == ["time", "recorded_at", "seq_count", "state", "position_3"]
    assert len(rows) >= 4 and rows[1][3] == "crs_control" and float(rows[1][4]) == pytest.approx(2.2)
    code, text = run(
        "--config", setup["config"], "query", "--kind", "hk_lifter", "--limit", "1", "--fields", "--hex"
    )
    assert code == 0 and "velocity=100" in text and "08 40" in text
    code, text = run("--config", setup["config"], "query", "--series", "hk_lifter.velocity", "--limit", "2")
    assert code == 0 and text.split()[1] == "100"


@pytest.mark.parametrize(
    ("text", "value"),
    [
        ("3", 3),
        ("0x10", 16),
        ("2.5", 2.5),
        ("true", True),
        ("int:7", 7),
        ("str:7", "7"),
        ("bool:0", False),
        ("float:1", 1.0),
        ("hello", "hello"),
    ],
)
def test_typed_values(text, value):
    parsed = cli._parse_typed(text)
    assert parsed == value and type(parsed) is type(value)


def test_export_unknown_field_is_refused(setup, capsys):
    run("--config", setup["config"], "send", "start", "--wait-ack")
    code, _ = run("--config", setup["config"], "export", "--kind", "ack", "--fields", "nope")
    assert code == cli.EXIT_USAGE and "no field 'nope'" in capsys.readouterr().err


def test_keygen_writes_a_private_key_file_once(tmp_path, capsys):
    path = tmp_path / "cfg" / "ground.key"
    code, text = run("keygen", str(path), "--key-id", "4")
    assert code == 0 and "mode 0600" in text
    assert oct(path.stat().st_mode & 0o777) == "0o600"
    assert KeyRing.load(path).key_ids == [4]
    assert run("keygen", str(path))[0] == cli.EXIT_USAGE and "--force" in capsys.readouterr().err
    assert run("keygen", str(path), "--force")[0] == 0 and KeyRing.load(path).key_ids == [1]
