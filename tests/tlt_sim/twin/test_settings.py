"""run.yaml is validated on load; a bad value names the file, the key and the reason."""

from __future__ import annotations

import pytest
import yaml
from tlt_sim.model.camera_sensor import DEFAULT_CAMERAS
from tlt_sim.twin.main import main
from tlt_sim.twin.settings import DEFAULT_SETTINGS, load_settings

from tlt_common.config_schema import ConfigError


def test_shipped_settings_load():
    s = load_settings()
    assert s.rtf == 1.0 and s.sync_period_s == 0.02
    assert s.camera_size("ars_x/d405_a") == (320, 240)


@pytest.mark.parametrize(
    ("key", "value", "reason"),
    [
        ("rtf", -1.0, "rtf"),
        ("sync_period_s", 0.5, "sync_period_s"),
        ("ur_hosts", {"ur_x": "10.0.0.2", "ur_y": "127.0.0.3"}, "loopback"),
    ],
)
def test_bad_values_are_refused_with_file_and_key(tmp_path, key, value, reason):
    doc = yaml.safe_load(DEFAULT_SETTINGS.read_text())
    doc[key] = value
    path = tmp_path / "run.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError) as err:
        load_settings(path)
    assert str(path) in str(err.value) and reason in str(err.value)


def test_main_refuses_bad_input_with_status_2(tmp_path, capsys):
    assert main(["--rtf", "-2", "--run-dir", str(tmp_path)]) == 2
    assert "--rtf" in capsys.readouterr().err
    assert main(["--scenario", str(tmp_path / "missing.yaml"), "--run-dir", str(tmp_path)]) == 2
    assert "missing.yaml" in capsys.readouterr().err
    cameras = tmp_path / "cameras.yaml"
    cameras.write_text(DEFAULT_CAMERAS.read_text().replace("seed: 0", "seed: -3"))
    assert main(["--cameras", str(cameras), "--run-dir", str(tmp_path)]) == 2
    assert "cameras.yaml: seed" in capsys.readouterr().err
    cameras.unlink()
    assert not list(tmp_path.iterdir()), "nothing was started"
