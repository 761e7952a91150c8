"""Scenario faults appear where their scenario files say."""

import numpy as np
import pytest
from tlt_sim.model import names
from tlt_sim.model.config import REPO_ROOT
from tlt_sim.model.scene import Scene

SCENARIOS = REPO_ROOT / "config" / "twin" / "scenarios"


@pytest.fixture
def scene_with(tmp_path):
    made = []

    def make(name: str) -> Scene:
        s = Scene(scenario=SCENARIOS / f"{name}.yaml", out_dir=tmp_path / name)
        made.append(s)
        return s

    yield make
    for s in made:
        s.close()


def _geoms(scene: Scene, body: str) -> set[str]:
    b = scene.model.body(body)
    return {scene.model.geom(g).name for g in range(b.geomadr[0], b.geomadr[0] + b.geomnum[0])}


def test_defective_struts_miss_a_fitting_or_are_bent(scene_with):
    scene = scene_with("defective_parts")
    missing, bent, good = (scene.part(f"vertical_dispenser_x/{i}") for i in range(3))
    assert f"{missing.body}/fitting_b" not in _geoms(scene, missing.body)
    assert f"{missing.body}/fitting_a" in _geoms(scene, missing.body)
    assert f"{bent.body}/tube#1" in _geoms(scene, bent.body)
    straight_end = np.array([0.0, 0.0, bent.length])
    assert np.linalg.norm(bent.ends["b"] - straight_end) > 0.04  # 8 degrees over half the strut
    assert np.allclose(good.ends["b"], [0.0, 0.0, good.length])
    assert {f"{good.body}/fitting_a", f"{good.body}/fitting_b"} <= _geoms(scene, good.body)


def test_camera_shows_only_one_end_fitting_of_the_defective_strut(scene_with):
    scene = scene_with("defective_parts")
    camera = names.d405_camera("ars_y", "a")
    for part, fittings in (
        ("vertical_dispenser_x/0", {"fitting_a"}),
        ("vertical_dispenser_x/2", {"fitting_a", "fitting_b"}),
    ):
        body = scene.part(part).body
        scene.place_in_view(part, camera, 0.45)
        seen = scene.render(camera, 160, 120).instances()
        shown = {n.rsplit("/", 1)[1] for n in seen if n.startswith(f"{body}/fitting_") and seen[n] > 5}
        assert shown == fittings
        assert seen.get(f"{body}/tube", 0) > 20
        scene.reset()


def test_grasp_slips_after_its_time(scene_with, mover):
    scene = scene_with("grasp_slip")
    arm, part = "ars_x", "vertical_dispenser_x/0"
    m = mover(scene, arm)
    m.pick(part)
    assert scene.holding(arm) == scene.part(part).body
    assert scene.run_until(lambda: scene.holding(arm) is None, 3.0, check_every=1)
    assert scene.time - scene.assembly.grasped_at[arm] == pytest.approx(2.0, abs=2 * scene.timestep)
    scene.advance(0.8)
    assert scene.part_state(part) == "dropped"
    closed = scene.edu["end_effector"]["jaw_range"][1]
    assert scene.position(names.grasp_joint(arm, "a")) == pytest.approx(closed, abs=0.02)  # nothing in it


def test_part_with_a_placement_offset_sits_off_centre_in_the_grasp(scene_with, mover):
    scene = scene_with("placement_offset")
    arm, part = "ars_x", "vertical_dispenser_x/0"
    mover(scene, arm).pick(part)
    scene.advance(0.3)
    info = scene.part(part)
    pos, rot = scene.body_pose(info.body)
    centre, _ = scene.assembly.grasp_line(arm)
    offset_in_part = rot.T @ (pos + rot @ info.grasps[0][0] - centre)
    assert offset_in_part == pytest.approx([0.012, 0.0, 0.0], abs=1e-3)
    assert np.linalg.norm(offset_in_part) > scene.mission.inspection["position_tolerance"]


def test_empty_dispenser_has_no_parts(scene_with):
    scene = scene_with("empty_dispenser")
    assert scene.dispenser_count("diagonal_dispenser_y") == 0
    assert not [p for p in scene.info.parts.values() if p.dispenser == "diagonal_dispenser_y"]
    assert scene.next_part("diagonal_dispenser_y") is None
    with pytest.raises(ValueError, match="empty"):
        scene.stage_member("bay1/diagonal/face_x1")
    assert (
        scene.dispenser_count("diagonal_dispenser_x")
        == scene.mission.dispensers["diagonal_dispenser_x"].count
    )


def test_device_faults_are_handed_on(scene_with):
    scene = scene_with("device_faults")
    faults = scene.scenario.device_faults
    assert faults["servo_failure"] == [{"link": "active_grippers", "servo_id": 2, "at_s": 30.0}]
    assert faults["limit_switch_stuck"][0]["switch"] == 4
    assert faults["link_drop"][0]["link"] == "ur_x"
