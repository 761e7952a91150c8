"""Across process boundaries: a CRS process built from link.yaml, commanded by the `tlt gsw` CLI."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest
import yaml

from tlt_common.ccsds.auth import write_key_file

CRS = textwrap.dedent(
    """
    import sys
    from tlt_common.ccsds.link_config import load_link_config
    from tlt_crs.ground_link import GroundLink

    def handle(command):
        print("handled", command.name, dict(command.params), flush=True)
        link.complete(command, detail="done in the CRS process")

    link = GroundLink.from_config(load_link_config(sys.argv[1]), on_command=handle)
    link.start()
    print(link.address[1], flush=True)
    sys.stdin.read()
    link.close()
    """
)


def write_config(tmp_path, key_file, name: str) -> str:
    path = tmp_path / name
    path.write_text(
        yaml.safe_dump(
            {
                "key_file": str(key_file),
                "key_id": 1,
                "crs": {
                    "bind_host": "127.0.0.1",
                    "bind_port": 0,
                    "gsw_host": "",
                    "gsw_port": 0,
                    "replay_state": str(tmp_path / "crs" / "replay.json"),
                },
                "gsw": {
                    "crs_host": "127.0.0.1",
                    "crs_port": 1,
                    "bind_host": "127.0.0.1",
                    "bind_port": 0,
                    "archive": str(tmp_path / "archive.sqlite"),
                    "command_state": str(tmp_path / "seq.json"),
                    "ack_timeout_s": 5.0,
                },
            }
        )
    )
    return str(path)


@pytest.fixture
def crs_process(tmp_path):
    key_file = write_key_file(tmp_path / "keys" / "ground.key", {1: os.urandom(32)}, {1: os.urandom(32)})
    config = write_config(tmp_path, key_file, "link.yaml")
    proc = subprocess.Popen(
        [sys.executable, "-c", CRS, config], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        port = int(proc.stdout.readline())
        yield {"proc": proc, "port": port, "config": config, "tmp": tmp_path}
    finally:
        proc.stdin.close()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        proc.stdout.close()


def gsw(config: str, port: int, *argv: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "tlt_gsw.cli", "--config", config, *argv, "--crs", f"127.0.0.1:{port}"],
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_cli_commands_a_crs_process(crs_process):
    done = gsw(
        crs_process["config"],
        crs_process["port"],
        "send",
        "set_blackboard_value",
        "key=inspection_attempts",
        "value=int:3",
        "--wait-complete",
    )
    assert done.returncode == 0, done.stderr
    assert "accepted" in done.stdout and "completed (done in the CRS process)" in done.stdout
    assert crs_process["proc"].stdout.readline().split(maxsplit=2) == [
        "handled",
        "set_blackboard_value",
        "{'key': 'inspection_attempts', 'value': 3}\n",
    ]


def test_wrong_key_gets_no_answer_and_no_action(crs_process):
    keys = crs_process["tmp"] / "keys"
    other = write_key_file(keys / "other.key", {1: os.urandom(32)}, {1: os.urandom(32)})
    config = write_config(crs_process["tmp"], other, "intruder.yaml")
    refused = gsw(config, crs_process["port"], "send", "start", "--wait-ack", "--timeout", "0.5")
    assert refused.returncode == 3 and "no acknowledgement" in refused.stdout
    accepted = gsw(crs_process["config"], crs_process["port"], "send", "pause", "--wait-ack")
    assert accepted.returncode == 0, accepted.stderr
    assert crs_process["proc"].stdout.readline().startswith("handled pause")  # the start never acted
