"""The driver nodes' ``main`` functions: a bad configuration is a clear error and exit code 2, not a crash."""

from __future__ import annotations

import pytest

from tlt_drivers.nodes import active_grippers, camera_mounts, ee, top_grippers


@pytest.mark.parametrize("main", [active_grippers.main, camera_mounts.main, top_grippers.main, ee.main_x])
def test_missing_config_file_exits_2_naming_the_file(main, tmp_path, capsys):
    missing = tmp_path / "nope.yaml"
    assert main(["--config", str(missing)]) == 2
    assert "nope.yaml" in capsys.readouterr().err


def test_bad_key_named(tmp_path, capsys):
    bad = tmp_path / "ag.yaml"
    bad.write_text(
        "component: active_grippers\nport: /dev/null\nspeed: 3\n"
        "joints: [{name: a, id: 1, mode: position, controller: trajectory, unit: rad, lower: 0.0, upper: 1.0,"
        " max_velocity: 1.0}]\n"
    )
    assert active_grippers.main(["--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "ag.yaml: speed: unknown key" in err


def test_joint_in_metres_without_lead_rejected(tmp_path, capsys):
    bad = tmp_path / "ee.yaml"
    bad.write_text(
        "component: ee_x\nport: /dev/null\n"
        "joints: [{name: w, id: 3, mode: extended_position, controller: group_position, unit: m, lower: 0.0,"
        " upper: 0.1, max_velocity: 0.01}]\n"
    )
    assert camera_mounts.main(["--config", str(bad)]) == 2
    assert "joints[0]: a joint in metres needs lead_m_per_rev" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["active_grippers", "camera_mounts", "ee_x", "ee_y"])
def test_shipped_dynamixel_configs_validate(name):
    from tlt_drivers.dynamixel.config import load_chain

    cfg = load_chain(f"config/hardware/{name}.yaml")
    assert cfg["component"] == name


def test_shipped_top_grippers_config_validates():
    from tlt_drivers.mightyzap.config import load_mightyzap

    assert len(load_mightyzap("config/hardware/top_grippers.yaml")["actuators"]) == 4
