"""Poses into the standard transform messages (tlt_common.ros.transform_messages)."""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from tf2_msgs.msg import TFMessage

from tlt_common.geometry.transforms import quaternion_to_rotation, rpy_matrix
from tlt_common.ros.stamps import stamp_seconds
from tlt_common.ros.transform_messages import TF_STATIC_QOS, frame_id, tf_message, transform_stamped


def test_a_pose_becomes_a_transform_of_the_named_frames_at_its_time():
    rot = rpy_matrix([0.3, -0.4, 2.0])
    msg = transform_stamped("/world", "ars_x/ee", [1.0, -2.0, 0.5], rot, 12.25)
    assert msg.header.frame_id == "world" and msg.child_frame_id == "ars_x/ee"
    assert stamp_seconds(msg.header.stamp) == pytest.approx(12.25)
    t = msg.transform.translation
    assert (t.x, t.y, t.z) == (1.0, -2.0, 0.5)
    q = msg.transform.rotation
    assert np.allclose(quaternion_to_rotation([q.x, q.y, q.z, q.w]), rot)


def test_ground_truth_poses_become_one_tf_message_that_survives_the_wire():
    poses = {
        "payload": (np.array([0.375, 0.375, 1.2]), np.eye(3)),
        "part/vertical_dispenser_x/0": (np.array([-0.5, 0.9, 0.4]), rpy_matrix([0.0, 1.5707963, 0.2])),
    }
    msg = deserialize_message(serialize_message(tf_message("world", poses, 3.0)), TFMessage)
    assert [m.child_frame_id for m in msg.transforms] == list(poses)
    for m in msg.transforms:
        assert m.header.frame_id == "world" and stamp_seconds(m.header.stamp) == 3.0
        p, r = poses[m.child_frame_id]
        t, q = m.transform.translation, m.transform.rotation
        assert np.allclose([t.x, t.y, t.z], p)
        assert np.allclose(quaternion_to_rotation([q.x, q.y, q.z, q.w]), r, atol=1e-7)


def test_static_transforms_are_latched_and_frame_ids_are_never_empty():
    assert TF_STATIC_QOS.durability == DurabilityPolicy.TRANSIENT_LOCAL
    with pytest.raises(ValueError):
        frame_id("/")
