"""QoS a recorder subscribes with, and the publishers' QoS it stores for replay, as rosbag2 does.

The subscription adapts to what the publishers offer: reliable only if every publisher is
reliable (a reliable reader cannot match a best-effort writer), transient local only if every
publisher is (so latched samples such as ``/tf_static`` or the twin's segmentation labels are
delivered to a recorder that starts late; a transient-local reader cannot match a volatile writer).

Each MCAP channel stores the offered profiles under ``offered_qos_profiles`` as a YAML list in the
format of rosbag2 on Jazzy (metadata version 9: policy names as strings, durations as
``{sec, nsec}``), which is what ``ros2 bag play`` reads to re-create latched publishers, and what
:func:`playback_qos` (``tlt record play``) reads back the same way.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import yaml
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# Deep enough to take a transient-local publisher's whole history at once, and to ride out the
# seconds a loaded machine may not schedule the recorder (2 s of a 500 Hz topic).
SUBSCRIPTION_DEPTH = 1000


def _duration(value: Duration) -> dict[str, int]:
    ns = int(value.nanoseconds)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def qos_to_dict(profile: QoSProfile) -> dict[str, Any]:
    """One profile in rosbag2's metadata format (version 9)."""
    return {
        "history": profile.history.short_key,
        "depth": int(profile.depth),
        "reliability": profile.reliability.short_key,
        "durability": profile.durability.short_key,
        "deadline": _duration(profile.deadline),
        "lifespan": _duration(profile.lifespan),
        "liveliness": profile.liveliness.short_key,
        "liveliness_lease_duration": _duration(profile.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": bool(profile.avoid_ros_namespace_conventions),
    }


def offered_qos_yaml(profiles: Iterable[QoSProfile]) -> str:
    """The ``offered_qos_profiles`` channel metadata: a YAML list, one entry per publisher."""
    return yaml.safe_dump([qos_to_dict(p) for p in profiles], sort_keys=False, default_flow_style=False)


def subscription_qos(offered: Sequence[QoSProfile]) -> QoSProfile:
    """The QoS that receives from every publisher offering ``offered`` (see the module text)."""
    reliable = bool(offered) and all(p.reliability == ReliabilityPolicy.RELIABLE for p in offered)
    latched = bool(offered) and all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in offered)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=SUBSCRIPTION_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


def is_latched(profile: QoSProfile) -> bool:
    """Whether a subscription was made to receive publishers' stored (latched) samples."""
    return profile.durability == DurabilityPolicy.TRANSIENT_LOCAL


PLAYBACK_DEPTH = 10  # the least history a replaying publisher keeps


def playback_qos(offered_qos_profiles: str) -> QoSProfile:
    """The QoS to replay a channel with, from its stored ``offered_qos_profiles`` YAML.

    As ``ros2 bag play`` adapts to recorded offers: reliable only if every recorded publisher was,
    transient local only if every one was (a latched topic is latched again), keep-last with the
    deepest recorded history (at least :data:`PLAYBACK_DEPTH`). Metadata that is missing or
    unreadable gives reliable, volatile.
    """
    try:
        entries = yaml.safe_load(offered_qos_profiles) if offered_qos_profiles else None
    except yaml.YAMLError:
        entries = None
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries) or not entries:
        return QoSProfile(depth=PLAYBACK_DEPTH)
    reliable = all(e.get("reliability") == ReliabilityPolicy.RELIABLE.short_key for e in entries)
    latched = all(e.get("durability") == DurabilityPolicy.TRANSIENT_LOCAL.short_key for e in entries)
    depths = [e.get("depth") for e in entries if isinstance(e.get("depth"), int)]
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=max([PLAYBACK_DEPTH, *depths]),
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )
