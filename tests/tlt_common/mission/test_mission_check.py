"""The mission check command: valid files summarised, invalid ones named with key and reason."""

from __future__ import annotations

from pathlib import Path

from tlt_common.mission.check import main
from tlt_common.mission.schema import load_mission
from tlt_common.mission.tower_model import TowerModel

MISSIONS = Path(__file__).resolve().parents[3] / "missions"


def test_valid_missions(capsys):
    assert main([str(p) for p in sorted(MISSIONS.glob("*.yaml"))]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 3 and all(line.startswith("ok ") for line in out)
    assert "mission 'ten_bay', 10 bay(s), 94 members" in "\n".join(out)


def test_invalid_mission_and_model(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: 1\nname: x\n")
    assert main([str(bad), str(MISSIONS / "one_bay.yaml")]) == 1
    assert f"INVALID {bad}: bay_count: missing required key" in capsys.readouterr().out

    state = tmp_path / "tower.json"
    model = TowerModel(load_mission(MISSIONS / "one_bay.yaml"), state)
    model.place("bay1/cross_frame")
    assert main([str(MISSIONS / "one_bay.yaml"), "--model", str(state)]) == 0
    assert "revision 1, 0 bay(s) built, 12 NOT_PLACED, 1 PLACED" in capsys.readouterr().out
    assert main([str(MISSIONS / "two_bay.yaml"), "--model", str(state)]) == 1
    assert "belongs to mission 'one_bay'" in capsys.readouterr().out
