"""The dispenser tag mounting rule's settings, read without the vision (tlt_common.mission.tag_mounts):
the same values the vision node validates and uses, and a bad file refused with the key named."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from tlt_common.config_schema import ConfigError, load_yaml
from tlt_common.mission.schema import load_mission
from tlt_common.mission.tag_mounts import (
    APRILTAG_CONFIG,
    VISION_CONFIG,
    TagMounting,
    printed_size,
    tag_mount,
)
from tlt_vision.apriltag import TagConfig
from tlt_vision.node_config import load_config


def test_the_settings_are_the_vision_configurations():
    mounting = TagMounting.load()
    assert mounting.tag_side == pytest.approx(TagConfig.load().tag_side)
    assert dict(mounting.mount) == load_config().raw["tag_mount"]
    # The printed plate of apriltag.yaml (one quiet-zone cell each side) is what printed_size gives.
    assert printed_size(mounting.tag_side) == pytest.approx(load_yaml(APRILTAG_CONFIG)["printed_size"])


def test_pose_is_the_rule_for_every_dispenser_and_a_fuller_rack_carries_its_tag_higher():
    mounting = TagMounting.load()
    one, two = load_mission("missions/one_bay.yaml"), load_mission("missions/two_bay.yaml")
    for dispenser in one.dispensers:
        expected = tag_mount(mounting.mount, one, dispenser, mounting.tag_side)
        np.testing.assert_allclose(mounting.pose(one, dispenser), expected)
    rack = "vertical_dispenser_x"
    assert two.dispensers[rack].count > one.dispensers[rack].count
    assert mounting.pose(two, rack)[2, 3] > mounting.pose(one, rack)[2, 3]


def test_a_missing_or_bad_setting_is_refused_naming_the_key(tmp_path):
    vision = load_yaml(VISION_CONFIG)
    del vision["tag_mount"]["slot_pitch"]
    bad_vision = tmp_path / "node.yaml"
    bad_vision.write_text(yaml.safe_dump(vision))
    with pytest.raises(ConfigError, match=r"tag_mount\.slot_pitch"):
        TagMounting.load(bad_vision, APRILTAG_CONFIG)

    tags = load_yaml(APRILTAG_CONFIG)
    tags["quiet_zone_cells"] = -1
    bad_tags = tmp_path / "apriltag.yaml"
    bad_tags.write_text(yaml.safe_dump(tags))
    with pytest.raises(ConfigError, match="quiet_zone_cells"):
        TagMounting.load(VISION_CONFIG, bad_tags)
