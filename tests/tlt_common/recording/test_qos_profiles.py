"""The recorder's subscription QoS adapts to the publishers'; their QoS is stored as rosbag2 does."""

from __future__ import annotations

import yaml
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from tlt_common.recording.qos_profiles import (
    PLAYBACK_DEPTH,
    SUBSCRIPTION_DEPTH,
    is_latched,
    offered_qos_yaml,
    playback_qos,
    subscription_qos,
)

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
VOLATILE = QoSProfile(depth=10)
BEST_EFFORT = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)


def test_all_latched_reliable_publishers_give_a_latched_reliable_subscription():
    qos = subscription_qos([LATCHED, LATCHED])
    assert qos.reliability == ReliabilityPolicy.RELIABLE
    assert is_latched(qos)
    assert qos.depth == SUBSCRIPTION_DEPTH


def test_one_weaker_publisher_weakens_the_subscription_so_it_matches_all():
    mixed = subscription_qos([LATCHED, VOLATILE])
    assert not is_latched(mixed) and mixed.reliability == ReliabilityPolicy.RELIABLE
    lossy = subscription_qos([VOLATILE, BEST_EFFORT])
    assert lossy.reliability == ReliabilityPolicy.BEST_EFFORT


def test_offered_profiles_yaml_has_rosbag2_version_9_fields():
    profile = QoSProfile(
        depth=3, durability=DurabilityPolicy.TRANSIENT_LOCAL, deadline=Duration(seconds=1, nanoseconds=500)
    )
    loaded = yaml.safe_load(offered_qos_yaml([profile, BEST_EFFORT]))
    assert loaded[0] == {
        "history": "keep_last",
        "depth": 3,
        "reliability": "reliable",
        "durability": "transient_local",
        "deadline": {"sec": 1, "nsec": 500},
        "lifespan": {"sec": 0, "nsec": 0},
        "liveliness": "system_default",
        "liveliness_lease_duration": {"sec": 0, "nsec": 0},
        "avoid_ros_namespace_conventions": False,
    }
    assert loaded[1]["reliability"] == "best_effort"


def test_a_replay_publishes_latched_topics_latched_again():
    qos = playback_qos(offered_qos_yaml([LATCHED, LATCHED]))
    assert qos.reliability == ReliabilityPolicy.RELIABLE
    assert qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert qos.depth == PLAYBACK_DEPTH


def test_a_replay_offers_no_more_than_every_recorded_publisher_did():
    qos = playback_qos(offered_qos_yaml([LATCHED, BEST_EFFORT, QoSProfile(depth=50)]))
    assert qos.reliability == ReliabilityPolicy.BEST_EFFORT
    assert qos.durability == DurabilityPolicy.VOLATILE
    assert qos.depth == 50  # the deepest recorded history


def test_missing_or_unreadable_stored_qos_replays_reliable_volatile():
    for text in ("", "[", "just text", "- 3\n", "[]"):
        qos = playback_qos(text)
        assert qos.reliability == ReliabilityPolicy.RELIABLE, text
        assert qos.durability == DurabilityPolicy.VOLATILE, text
        assert qos.depth == PLAYBACK_DEPTH, text
