"""Scenario 4 (issue "whole system"): a defective strut is caught at inspection, discarded and
replaced; the dispenser count and telemetry show it.

The whole system runs on the twin (config/launch/system_twin.yaml, tests/system/system_run.py)
with a twin scenario in which the first vertical of ARS X's dispenser lacks its lower end fitting
(config/twin/scenarios/defective_parts.yaml has it and a bent one after it; one is enough here).
ARS X takes it for the first far vertical once the cross frame is in place; the CRS's ZED
inspection must fail it with the reason (an INSPECTION_FAILED event), ARS X discards it and takes
the next, which passes (INSPECTION_PASSED) and is placed. Then the mission telemetry counts one
part discarded and two members placed, and the CRS's persisted tower model (the run's
tower_model.json) has taken two verticals from that dispenser and discarded one. In the twin
(ground truth in the run's recording) the defective part lies off the tower and its replacement
stands at the vertical's place.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from tlt_common.ccsds.reasons import AckStage
from tlt_common.mission.schema import load_mission

_spec = importlib.util.spec_from_file_location("system_run", Path(__file__).with_name("system_run.py"))
system_run = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(system_run)
SystemRun = system_run.SystemRun

pytestmark = [pytest.mark.system, pytest.mark.timeout(600)]

MEMBER = "bay1/vertical/x0_y1"  # ARS X's first vertical: the dispenser's part 0
DISPENSER = "vertical_dispenser_x"
SCENARIO = {
    "name": "defective_vertical",
    "description": "the first vertical of ARS X's dispenser lacks end fitting b",
    "faults": {"defective_parts": [
        {"dispenser": DISPENSER, "index": 0, "defect": "missing_end_fitting", "end": "b"},
    ]},
}


def _inspection(code: str):
    return lambda p: p.kind == "event" and p.fields["code"] == code and p.fields["text"].startswith(MEMBER)


def test_a_defective_vertical_is_caught_discarded_and_replaced(tmp_path):
    scenario = tmp_path / "defective_vertical.yaml"
    scenario.write_text(yaml.safe_dump(SCENARIO))
    with SystemRun(tmp_path / "run", scenario=str(scenario)) as run:
        run.start()
        run.wait_ready()
        assert run.start_build().stage is AckStage.COMPLETED
        failed, _ = run.wait_through_faults(_inspection("INSPECTION_FAILED"), 400,
                                            f"{MEMBER}'s first part failing inspection", clear_faults=3)
        assert "end fitting" in failed.fields["text"], failed.fields
        mark = len(run.packets)
        run.wait_through_faults(_inspection("INSPECTION_PASSED"), 150, f"{MEMBER}'s replacement passing",
                                since=mark)
        done, _ = run.wait_through_faults(
            lambda p: p.kind == "mission_step" and p.fields["members_placed"] >= 2, 150,
            f"{MEMBER} placed", since=mark)
        assert done.fields["parts_discarded"] == 1, done.fields
        # One failure, then the pass: the replacement was inspected once.
        codes = [f["code"] for f in run.events() if f["text"].startswith(MEMBER) and "INSPECT" in f["code"]]
        assert codes == ["INSPECTION_FAILED", "INSPECTION_PASSED"], codes
        run.poll(2.0)
        assert run.stop() == 0

    model = json.loads((run.run_dir / "tower_model.json").read_text())
    count = load_mission(system_run.ROOT / "missions" / "one_bay.yaml").dispensers[DISPENSER].count
    assert model["dispensers"][DISPENSER] == {"remaining": count - 2, "discarded": 1}, model["dispensers"]

    # The twin's ground truth at the end: part 1 at the vertical's place (its body frame at an end
    # or the middle, whichever the twin uses), part 0 nowhere near it.
    last = {}
    for msg in run.recorded("/twin/ground_truth"):
        t = msg.transform.translation
        last[msg.child_frame_id] = np.array([t.x, t.y, t.z])
    mission = load_mission(system_run.ROOT / "missions" / "one_bay.yaml")
    tower = last["tower"]
    ends = [tower + np.asarray(p) for _, p in mission.member(MEMBER).joints]
    place = np.array([*ends, (ends[0] + ends[1]) / 2])
    off = {i: np.linalg.norm(place - last[f"part/{DISPENSER}/{i}"], axis=1).min() for i in (0, 1)}
    assert off[1] < 0.02 and off[0] > 0.2, (off, last[f"part/{DISPENSER}/0"], last[f"part/{DISPENSER}/1"])
