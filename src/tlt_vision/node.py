"""``tlt-vision``: the vision node serving part and bay inspection, alignment and dispenser tags.

Services (names from :mod:`tlt_common.ros_names`; paper §V.E), each answered by its handler in
:mod:`tlt_vision.services`:

* ``VISION_INSPECT_PART`` (``InspectPart``): a strut (``vertical``, ``diagonal``) or a
  ``cross_frame`` held in front of a lifter ZED, or ``rivet`` with member id ``<ars>/<gun>``: is a
  rivet in that EE gun (seen by the D405 beside it). The report passes or fails with every reason.
* ``VISION_INSPECT_BAY`` (``InspectBay``): the four corner joints of bay N seen by the inward ZEDs,
  placed in the world through the transform tree and matched to the mission's joints.
* ``VISION_CHECK_ALIGNMENT`` (``CheckAlignment``): the member's held part, from the end pieces the
  EE cameras of the named camera's arm see, in the world, against the mission's joint positions;
  the answered pose is the tool pose that holds the part where it is seen (the ARS's convention).
* ``VISION_LOCATE_TAG`` (``LocateTag``): the dispenser's AprilTag (cv2.aruco, IPPE square) in the
  named camera's RGB; the answered pose is the dispenser's frame in the world (the tag marks it).
* ``VISION_VERIFY_JOINT`` (``VerifyJoint``): a riveted joint right after its shot, from one frame of
  the named EE camera, at the joint the caller's model gives: good, no_head, unseated, wrong_hole,
  or cannot_judge (:mod:`tlt_vision.services.verify_joint`).

Each certified pose a request finds goes out on ``/tf`` (child of the camera's optical frame,
``vision/<camera>/<class>_<n>``) and as markers on ``VISION_MARKERS``
(:mod:`tlt_vision.pose_broadcast`). And the node publishes ``VISION_STATUS``
(``diagnostic_msgs/DiagnosticStatus``, latched: :mod:`tlt_common.ros.readiness`): why a request
could not place its camera yet (``no joint state yet for ur_x_shoulder_pan_joint ...``) until
every joint the cameras and end effectors need has been heard of, then ``ready``; the CRS refuses
Start until then.

Each request takes one fresh frame of its camera (:mod:`tlt_vision.services.frame_source`: subscribed
only while it waits, at most ``timeouts.frame_s``), segments it (``segmentation.source``: the
twin's labels or Mask R-CNN), turns the part's instances into point clouds and certified C-3PO
poses (:mod:`tlt_vision.pipeline`), and decides (:mod:`tlt_vision.inspection`). Camera poses come
from :mod:`tlt_vision.frames`. Every failure (unknown camera, no frame in time, part not in view,
no certified pose, no joint state) is an answer with the reason, never an exception or a hang.
Each service has its own callback group, so one slow request does not hold the others' replies.
The node runs on ROS time (``--ros-args -p use_sim_time:=true`` under the twin). This module
builds the handlers with their collaborators, subscribes to the joint states the camera poses
need, registers the services, and holds ``main``.

Weights files are checked when the node is built: a missing or mismatched file stops it there,
with the path and the expected shape named.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import ExternalShutdownException
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from tlt_interfaces.msg import EndEffectorState
from tlt_interfaces.srv import CheckAlignment, InspectBay, InspectPart, LocateTag, VerifyJoint

from tlt_common import ros_names
from tlt_common.config_schema import ConfigError
from tlt_common.mission.schema import Mission, load_mission
from tlt_common.ros.direct_executor import DirectMultiThreadedExecutor, QuickCallbackGroup
from tlt_common.ros.executor_stop import stop_executor
from tlt_common.ros.interpreter_lock import share_the_interpreter_quickly
from tlt_common.ros.lean_node import LeanNode
from tlt_common.ros.readiness import ReadinessPublisher
from tlt_common.ros.rosout_logging import RosoutHandler, forward_logging_to_rosout, init_rclpy
from tlt_common.ros.spin_loop import spin
from tlt_common.ros.stop_signals import stop_on_signals
from tlt_vision.apriltag import TagConfig, TagLocator
from tlt_vision.camera_frames import FrameGrabber, SegmentationLabels
from tlt_vision.frames import CameraRig
from tlt_vision.inspection.rivet_joint import RivetJointLimits
from tlt_vision.node_config import DEFAULT_CONFIG, VisionConfig, load_config
from tlt_vision.node_config_schema import SEGMENTATION_SOURCES
from tlt_vision.part_inspection import PartInspector
from tlt_vision.pose_broadcast import PoseBroadcaster
from tlt_vision.segmentation_source import MaskRcnnSegmenter, TwinLabels
from tlt_vision.self_filter import EeSelfFilter
from tlt_vision.services.check_alignment import CheckAlignmentHandler
from tlt_vision.services.detector import Detector
from tlt_vision.services.frame_poser import FramePoser
from tlt_vision.services.frame_source import FrameSource
from tlt_vision.services.inspect_bay import InspectBayHandler
from tlt_vision.services.inspect_part import InspectPartHandler
from tlt_vision.services.locate_tag import LocateTagHandler
from tlt_vision.services.verify_joint import VerifyJointHandler
from tlt_vision.weights import WeightsError

log = logging.getLogger("tlt.vision")


class VisionNode(LeanNode):
    """The vision services (see the module docstring): builds each service's handler with its
    collaborators, subscribes to the joint states the camera poses need, and serves."""

    def __init__(
        self, config: VisionConfig, mission: Mission | None = None, name: str = "vision", **node_kwargs: Any
    ) -> None:
        super().__init__(name, **node_kwargs)
        self.config = config
        raw = config.raw
        self.mission = mission or load_mission(config.mission_path)
        self.inspector = PartInspector(config, self.mission)
        self.rig = CameraRig(config)
        self.ee_filter = EeSelfFilter.from_config(raw["ee_self_filter"])
        self._set_up_torch(raw["torch_threads"])
        self.tags = TagLocator(TagConfig.load())

        sensors = QuickCallbackGroup()  # stores only: called on the executor's own thread
        self.labels = SegmentationLabels(self, raw["topics"]["segmentation_labels"], sensors)
        seg = raw["segmentation"]
        if seg["source"] == "mask_rcnn":
            segmenter: Any = MaskRcnnSegmenter.from_config(self.config)
        else:
            segmenter = TwinLabels(lambda: self.labels.wait(0.0))
        self.frames = FrameSource(FrameGrabber(self, raw["topics"]["image"]), config, self._now)
        self.detector = Detector(segmenter, config)
        # Latched for the CRS, which refuses Start until every camera can be placed.
        self.readiness = ReadinessPublisher(self, ros_names.VISION_STATUS, "vision")
        self.readiness.say(self.rig.not_ready())
        self._subscribe_joint_states(sensors)

        logger = self.get_logger()
        # Every certified pose a request finds, on /tf and as markers (docs/live-view.md).
        self.pose_broadcast = PoseBroadcaster(self)
        poser = FramePoser(self.inspector, config, self.pose_broadcast)
        self.part_handler = InspectPartHandler(
            frames=self.frames,
            detector=self.detector,
            poser=poser,
            inspector=self.inspector,
            rig=self.rig,
            ee_filter=self.ee_filter,
            config=config,
            clock=self._now,
            logger=logger,
        )
        self.bay_handler = InspectBayHandler(
            frames=self.frames,
            detector=self.detector,
            poser=poser,
            rig=self.rig,
            mission=self.mission,
            tolerances=self.inspector.tol,
            config=config,
            clock=self._now,
            logger=logger,
        )
        self.alignment_handler = CheckAlignmentHandler(
            frames=self.frames,
            detector=self.detector,
            poser=poser,
            rig=self.rig,
            mission=self.mission,
            parts=self.inspector.parts,
            tolerances=self.inspector.tol,
            config=config,
            clock=self._now,
            logger=logger,
        )
        self.tag_handler = LocateTagHandler(
            frames=self.frames,
            rig=self.rig,
            tags=self.tags,
            mission=self.mission,
            config=config,
            logger=logger,
        )
        self.joint_handler = VerifyJointHandler(
            frames=self.frames,
            detector=self.detector,
            rig=self.rig,
            parts=self.inspector.parts,
            limits=RivetJointLimits(head_radius=float(self.inspector.parts["rivet_radius"])),
            clock=self._now,
            logger=logger,
        )
        self.vision_services = [
            self.create_service(srv, name, cb, callback_group=MutuallyExclusiveCallbackGroup())
            for srv, name, cb in (
                (InspectPart, ros_names.VISION_INSPECT_PART, self.part_handler),
                (InspectBay, ros_names.VISION_INSPECT_BAY, self.bay_handler),
                (CheckAlignment, ros_names.VISION_CHECK_ALIGNMENT, self.alignment_handler),
                (LocateTag, ros_names.VISION_LOCATE_TAG, self.tag_handler),
                (VerifyJoint, ros_names.VISION_VERIFY_JOINT, self.joint_handler),
            )
        ]
        self.get_logger().info(
            f"vision ready: mission {self.mission.name}, segmentation {seg['source']}, "
            f"cameras {', '.join(config.cameras)}"
        )

    @staticmethod
    def _set_up_torch(threads: int) -> None:
        """Fix torch's thread count (config ``torch_threads``) and import its compiler stack, which
        the first optimiser made pulls in (seconds of CPU), at start-up rather than inside the first
        request's time."""
        import torch

        torch.set_num_threads(threads)
        torch.optim.Adam([torch.zeros(1, requires_grad=True)])

    def _subscribe_joint_states(self, group: Any) -> None:
        def on_joints(msg: JointState) -> None:
            self.rig.joints.update(list(msg.name), list(msg.position), self._msg_time(msg))
            if not self.readiness.ready:
                self.readiness.say(self.rig.not_ready())

        def on_ee(msg: EndEffectorState) -> None:
            self.rig.joints.update(list(msg.joint_names), list(msg.position), self._msg_time(msg))
            if not self.readiness.ready:
                self.readiness.say(self.rig.not_ready())

        components = {ros_names.CAMERA_MOUNTS} if self.rig.lifter else set()
        arms = set(self.rig.arms)
        components |= {ros_names.ur(a) for a in arms}
        for c in sorted(components):
            self.create_subscription(
                JointState, ros_names.joint_states_topic(c), on_joints, 10, callback_group=group
            )
        for a in sorted(arms):
            self.create_subscription(
                EndEffectorState, ros_names.state_topic(ros_names.ee(a)), on_ee, 10, callback_group=group
            )

    def _msg_time(self, msg: Any) -> float:
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        return t if t > 0 else self._now()

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9


def build_node(
    config_path: str | Path = DEFAULT_CONFIG, mission: str | Path | None = None, **kw: Any
) -> VisionNode:
    """Load the configuration and build the node; ConfigError or WeightsError when refused."""
    return VisionNode(load_config(config_path, mission), **kw)


# The twin's camera models (config/twin/cameras.yaml) and their exact diagnosis.
CAMERA_MODELS = ("realistic", "exact")


def main(argv: list[str] | None = None) -> int:
    """``tlt-vision [--config node.yaml] [--mission M.yaml] [--camera-model realistic|exact]
    [--segmentation twin_labels|mask_rcnn] [--ros-args ...]``; 2 when refused."""
    argv = list(sys.argv[1:] if argv is None else argv)
    ros_args: list[str] = []
    if "--ros-args" in argv:
        at = argv.index("--ros-args")
        argv, ros_args = argv[:at], argv[at:]
    parser = argparse.ArgumentParser(prog="tlt-vision", description="The TLT vision node (paper §V.E).")
    parser.add_argument("--config", type=Path, default=DEFAULT_CONFIG, help="vision node configuration")
    parser.add_argument("--mission", type=Path, help="mission file (overrides the configuration's)")
    parser.add_argument(
        "--camera-model",
        choices=CAMERA_MODELS,
        default="realistic",
        help="exact: the depth is the twin's exact render (tlt twin run --camera-model "
        "exact), for diagnosis; realistic: each camera's noise as node.yaml gives it",
    )
    parser.add_argument(
        "--segmentation",
        type=lambda text: text.strip() or None,  # a launch set passes an unset variable as ""
        metavar="|".join(SEGMENTATION_SOURCES),
        help="where the masks come from (overrides segmentation.source; empty: the file's)",
    )
    args = parser.parse_args(argv)
    if args.segmentation not in (None, *SEGMENTATION_SOURCES):
        parser.error(f"--segmentation: {args.segmentation!r} is not one of {', '.join(SEGMENTATION_SOURCES)}")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    try:
        config = load_config(args.config, args.mission)
        if args.camera_model == "exact":
            config = config.with_exact_depth()
        if args.segmentation is not None:
            config = config.with_segmentation(args.segmentation)
        mission = load_mission(config.mission_path)
    except ConfigError as exc:
        print(f"tlt-vision: refused: {exc}", file=sys.stderr)
        return 2
    share_the_interpreter_quickly()  # poses are computed beside the executor's busy threads
    # rclpy's own handler would shut the context down under a pose being computed on an executor
    # thread: a signal asks the spin loop to end instead (tlt_common/ros/stop_signals.py).
    stop = stop_on_signals()
    init_rclpy(["tlt-vision", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node = None
    logs: RosoutHandler | None = None
    try:
        try:
            node = VisionNode(config, mission)
        except (ConfigError, WeightsError, KeyError) as exc:
            print(f"tlt-vision: refused: {exc}", file=sys.stderr)
            return 2
        logs = forward_logging_to_rosout(node)
        executor = DirectMultiThreadedExecutor(num_threads=8)
        executor.add_node(node)
        try:
            spin(executor, stop=lambda: bool(stop))
        except ExternalShutdownException:  # a context shut down by someone else
            pass
        finally:
            for exc in stop_executor(executor, 2.0):  # before the node's handles go
                node.get_logger().warning(f"a callback ended with {exc!r} at shutdown")
    finally:
        if logs is not None:
            logs.remove()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
