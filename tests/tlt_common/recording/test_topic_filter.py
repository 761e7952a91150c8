"""Which topics a recording takes."""

from __future__ import annotations

import pytest

from tlt_common.recording.topic_filter import TopicFilter


def test_everything_but_images_by_default():
    topics = TopicFilter()
    assert topics.accepts("/lifter/state")
    assert topics.accepts("/ars_x/add_member/_action/feedback")
    assert not topics.accepts("/cameras/crs/image")
    assert not topics.accepts("/cameras/crs/image_raw")
    assert not topics.accepts("/cameras/crs/depth")
    assert topics.accepts("/cameras/crs/camera_info")
    assert topics.accepts("/cameras/crs/image_count")
    assert not topics.accepts("/cameras/zed_1/rgb", "sensor_msgs/msg/Image")
    assert not topics.accepts("/cameras/zed_1/segmentation", "sensor_msgs/msg/Image")
    assert not topics.accepts("/cams/front/compressed", "sensor_msgs/msg/CompressedImage")
    assert topics.accepts("/cameras/zed_1/camera_info", "sensor_msgs/msg/CameraInfo")


def test_images_on_request():
    assert TopicFilter(include_images=True).accepts("/cameras/crs/image")
    assert TopicFilter(include_images=True).accepts("/cameras/zed_1/rgb", "sensor_msgs/msg/Image")


def test_exclusions_match_the_whole_name():
    topics = TopicFilter(exclude=["/rosout", ".*/_action/status"])
    assert not topics.accepts("/rosout")
    assert topics.accepts("/rosout_agg")
    assert not topics.accepts("/ars_y/affix_member/_action/status")


def test_allow_list_takes_only_its_topics_images_included_but_not_excluded_ones():
    topics = TopicFilter(topics=["/a", "/cam/image", "/b"], exclude=["/b"])
    assert topics.accepts("/a")
    assert topics.accepts("/cam/image")
    assert topics.accepts("/cam/image", "sensor_msgs/msg/Image")
    assert not topics.accepts("/b")
    assert not topics.accepts("/c")


def test_a_bad_pattern_is_named():
    with pytest.raises(ValueError, match=r"exclude pattern '\(' is not a regular expression"):
        TopicFilter(exclude=["("])
