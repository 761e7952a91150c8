"""Rivet outcomes: the gun's offset and angle against the fastener's tolerances, injected faults."""

import numpy as np
import pytest
from tlt_sim.model.config import load_edu
from tlt_sim.model.rivet_outcomes import (
    EFFECTS,
    FAULT_KINDS,
    KINDS,
    RandomRivetFaults,
    RivetFaultPlan,
    bar_angle_deg,
    judge_geometry,
)

RIVETS = load_edu()[0]["rivets"]


@pytest.mark.parametrize(
    ("offset", "angle", "kind"),
    [
        (0.0, 0.0, "good"),
        (0.9 * RIVETS["max_offset"], 0.9 * RIVETS["max_angle_deg"], "good"),
        (1.1 * RIVETS["max_offset"], 0.0, "proud_head"),
        (0.0, 1.1 * RIVETS["max_angle_deg"], "partial_grip"),
        (1.1 * RIVETS["max_offset"], 1.1 * RIVETS["max_angle_deg"], "proud_head"),
    ],
)
def test_a_gun_within_tolerance_sets_a_good_rivet_and_one_past_it_does_not(offset, angle, kind):
    judged, reason = judge_geometry(offset, angle, RIVETS)
    assert judged == kind
    assert ("within tolerance" in reason) == (kind == "good")


def test_bar_angle_is_taken_either_way_along_the_bar_and_the_member():
    bar = np.array([0.0, 0.0, 1.0])
    tilted = np.array([np.sin(np.radians(12.0)), 0.0, np.cos(np.radians(12.0))])
    assert bar_angle_deg(bar, tilted) == pytest.approx(12.0)
    assert bar_angle_deg(-bar, 3 * tilted) == pytest.approx(12.0)
    assert bar_angle_deg(bar, np.array([1.0, 0.0, 0.0])) == pytest.approx(90.0)


def test_every_kind_has_its_effect_and_only_a_good_rivet_holds_as_built():
    assert set(EFFECTS) == set(KINDS)
    assert [k for k, e in EFFECTS.items() if e.joins and e.softer is None] == ["good"]
    assert [k for k, e in EFFECTS.items() if not e.spent] == ["misfire"]
    assert EFFECTS["loose"].head == EFFECTS["good"].head  # a loose joint looks good


def test_chosen_faults_hit_their_joint_and_shot_only():
    plan = RivetFaultPlan({("bay1/vertical/x0_y0", "bay0/x0_y0", 2): "misfire"})
    assert plan.injected("bay1/vertical/x0_y0", "bay0/x0_y0", 1) is None
    assert plan.injected("bay1/vertical/x0_y0", "bay0/x0_y0", 2) == "misfire"
    assert plan.injected("bay1/vertical/x0_y0", "bay1/x0_y0", 2) is None


def test_random_faults_depend_on_seed_and_joint_not_on_order_and_spare_second_shots():
    joints = [(f"m{i}", f"j{i % 7}") for i in range(400)]
    faults = RandomRivetFaults(rate=0.25, seed=11)
    drawn = [faults.draw(m, j) for m, j in joints]
    assert drawn == [faults.draw(m, j) for m, j in reversed(joints)][::-1]
    assert drawn != [RandomRivetFaults(rate=0.25, seed=12).draw(m, j) for m, j in joints]
    hit = [k for k in drawn if k is not None]
    assert 0.18 < len(hit) / len(joints) < 0.32
    assert set(hit) == set(FAULT_KINDS)  # each kind turns up
    assert all(RandomRivetFaults(rate=0.0, seed=11).draw(m, j) is None for m, j in joints)
    only = RandomRivetFaults(rate=1.0, seed=3, kinds=("loose",))
    assert {only.draw(m, j) for m, j in joints} == {"loose"}
    plan = RivetFaultPlan({}, only)
    assert plan.injected("m0", "j0", 1) == "loose"
    assert plan.injected("m0", "j0", 2) is None  # a second shot can repair what the first spoilt
