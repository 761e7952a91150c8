"""The UR arm YAML files and their validation."""

from __future__ import annotations

import pytest
import yaml

from tlt_common.config_schema import ConfigError
from tlt_drivers.ur.config import CONFIG_DIR, load_ur_config, with_link_timeout, with_rtde_frequency


@pytest.mark.parametrize("arm,host", [("x", "127.0.0.2"), ("y", "127.0.0.3")])
def test_shipped_configs_load(arm: str, host: str) -> None:
    config = load_ur_config(CONFIG_DIR / f"ur_{arm}.yaml")
    assert config.component == f"ur_{arm}"
    assert config.host == host
    assert len(config.joint_names) == 6
    assert all(name.startswith(f"ur_{arm}_") for name in config.joint_names)


def _write(tmp_path, change) -> str:
    doc = yaml.safe_load((CONFIG_DIR / "ur_x.yaml").read_text())
    change(doc)
    path = tmp_path / "ur.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.mark.parametrize(
    "change,key,reason",
    [
        (lambda d: d.pop("host"), "host", "missing required key"),
        (lambda d: d.update(servo_gain=5000.0), "servo_gain", "at most 2000"),
        (lambda d: d["joints"].pop(), "joints", "expected the 6 joints"),
        (lambda d: d["joints"][2].update(max_position=7.0), "joints", "UR10e range"),
        (lambda d: d["joints"][0].update(max_velocity=3.0), "joints", "UR10e limit"),
        (
            lambda d: d.update(link_timeout_s=0.05, rtde_frequency_hz=10.0),
            "link_timeout_s",
            "one RTDE period",
        ),
        (lambda d: d.update(joint_state_rate_hz=200.0), "joint_state_rate_hz", "at most control_rate_hz"),
        (lambda d: d.update(colour="red"), "colour", "unknown key"),
    ],
)
def test_bad_values_are_rejected_naming_the_key(tmp_path, change, key: str, reason: str) -> None:
    path = _write(tmp_path, change)
    with pytest.raises(ConfigError) as err:
        load_ur_config(path)
    assert err.value.key == key
    assert reason in err.value.reason
    assert str(path) in str(err.value)


def test_node_main_refuses_a_bad_config_with_exit_status_2(tmp_path, capsys) -> None:
    from tlt_drivers.ur.node import main

    path = _write(tmp_path, lambda d: d.pop("joints"))
    assert main(["--config", str(path)]) == 2
    assert "joints" in capsys.readouterr().err


def test_a_launch_set_may_ask_another_rtde_rate_within_the_file_s_limits() -> None:
    path = CONFIG_DIR / "ur_x.yaml"
    config = load_ur_config(path)
    assert with_rtde_frequency(config, 125.0, path).rtde_frequency_hz == 125.0
    with pytest.raises(ConfigError, match="must be 1 to 500") as err:
        with_rtde_frequency(config, 1000.0, path)
    assert err.value.key == "rtde_frequency_hz"
    with pytest.raises(ConfigError, match="one RTDE period"):
        with_rtde_frequency(config, 1.5, path)  # the 0.5 s link timeout is shorter than a period


def test_a_launch_set_may_give_the_link_longer_to_go_quiet() -> None:
    path = CONFIG_DIR / "ur_x.yaml"
    config = load_ur_config(path)
    assert with_link_timeout(config, 1.5, path).link_timeout_s == 1.5
    with pytest.raises(ConfigError, match="one RTDE period") as err:
        with_link_timeout(config, 0.001, path)  # 500 Hz: a period is 2 ms
    assert err.value.key == "link_timeout_s"
    # Both overrides together: the rate is judged against the new timeout.
    slow = with_rtde_frequency(with_link_timeout(config, 1.5, path), 1.0, path)
    assert (slow.rtde_frequency_hz, slow.link_timeout_s) == (1.0, 1.5)


def test_node_main_refuses_an_rtde_rate_out_of_range_with_exit_status_2(capsys) -> None:
    from tlt_drivers.ur.node import main

    assert main(["--config", str(CONFIG_DIR / "ur_x.yaml"), "--rtde-frequency-hz", "0"]) == 2
    assert "rtde_frequency_hz" in capsys.readouterr().err


def test_node_main_refuses_a_link_timeout_within_one_period_with_exit_status_2(capsys) -> None:
    from tlt_drivers.ur.node import main

    assert main(["--config", str(CONFIG_DIR / "ur_x.yaml"), "--link-timeout-s", "0"]) == 2
    assert "link_timeout_s" in capsys.readouterr().err
