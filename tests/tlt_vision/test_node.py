"""The vision node against the twin: real service calls answered from the twin's rendered cameras.

The twin here is the real model (``tlt_sim.model.Scene``, scenario ``defective_parts``) with the
twin process's own stream publishers (``tlt_sim.twin.ros_streams``: ``/clock``, camera images
rendered only while subscribed, segmentation labels), stepped on a thread of this process so a
test can stage parts between steps. The drivers' joint states (``/camera_mounts/joint_states``,
``/ur_x/joint_states``, ``/ee_x/state`` with the width and grasp joints) are published from the
model's joints, stamped with sim time, as the driver nodes publish them on the twin. The vision
node runs on sim time.
"""

from __future__ import annotations

import contextlib
import queue
import signal
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from tf2_msgs.msg import TFMessage
from tlt_interfaces.msg import EndEffectorState
from tlt_interfaces.srv import CheckAlignment, InspectPart, LocateTag
from tlt_sim.model import names
from tlt_sim.model.camera_sensor import load_camera_sensors
from tlt_sim.model.scene import Scene
from tlt_sim.twin.ros_streams import CameraStreams, ClockPublisher
from tlt_sim.twin.settings import load_settings
from visualization_msgs.msg import MarkerArray

from tlt_ars.planning.reachability import TargetUnreachable, reach_target
from tlt_ars.planning.targets import dispenser_targets, placement_targets
from tlt_ars.planning.world import build_scene, load_scene_config
from tlt_common import ros_names
from tlt_common.config_schema import ConfigError, load_yaml
from tlt_common.geometry.transforms import pose_error, pose_matrix
from tlt_common.ros.spin_loop import spin
from tlt_vision.frames import FrameUnavailable, arm_joint_names, grasp_joint_names, width_joint_name
from tlt_vision.node import VisionNode, main
from tlt_vision.node_config import DEFAULT_CONFIG, config_from_dict, load_config

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "config" / "twin" / "scenarios" / "defective_parts.yaml"
CALL_S = 120.0


class TwinHost:
    """The model stepped on its own thread, with the twin's publishers and the drivers' joint states.
    Its cameras are the twin's realistic ones (config/twin/cameras.yaml), standing on their nominal
    mounts."""

    def __init__(self, context: Context, out_dir: Path) -> None:
        self.scene = Scene(scenario=SCENARIO, out_dir=out_dir)
        self.node = Node("twin", context=context)
        self.clock = ClockPublisher(self.node)
        self.cameras = CameraStreams(self.node, self.scene, load_settings(), load_camera_sensors())
        self.rendering = True
        self.mounts = self.node.create_publisher(
            JointState, ros_names.joint_states_topic("camera_mounts"), 10
        )
        self.arm = self.node.create_publisher(JointState, ros_names.joint_states_topic("ur_x"), 10)
        self.ee = self.node.create_publisher(EndEffectorState, ros_names.state_topic("ee_x"), 10)
        self.calls: queue.Queue = queue.Queue()
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()
        # The first render makes the GL context, which holds the interpreter for seconds on a
        # loaded machine; made here, it does not eat into the requests' frame timeout.
        self.do(lambda s: s.render(names.zed_camera(0), 320, 240), timeout=120.0)

    def do(self, fn, timeout: float = 30.0):
        """Run ``fn(scene)`` on the simulation thread between steps; returns its result."""
        done: queue.Queue = queue.Queue()
        self.calls.put((fn, done))
        ok, value = done.get(timeout=timeout)
        if not ok:
            raise value
        return value

    def _run(self) -> None:
        tick = 0
        while not self._stop.is_set():
            while not self.calls.empty():
                fn, done = self.calls.get()
                try:
                    done.put((True, fn(self.scene)))
                except Exception as exc:  # handed to the caller
                    done.put((False, exc))
            self.scene.step(5)  # one 10 ms sync period
            t = self.scene.time
            self.clock.publish(t)
            if self.rendering:
                self.cameras.publish_due(t)
            if tick % 5 == 0:
                self._joint_states(t)
            tick += 1
            time.sleep(0.002)  # let the other threads of this process in

    def _joint_states(self, t: float) -> None:
        s = self.scene
        stamp = rclpy.time.Time(seconds=t).to_msg()
        msg = JointState()
        msg.header.stamp = stamp
        msg.name = [names.camera_mount(i) for i in range(2)]
        msg.position = [s.position(n) for n in msg.name]
        self.mounts.publish(msg)
        arm = JointState()
        arm.header.stamp = stamp
        arm.name = arm_joint_names("ars_x")
        arm.position = [s.position(j) for j in names.arm_joints("ars_x")]
        self.arm.publish(arm)
        ee = EndEffectorState()
        ee.header.stamp = stamp
        ee.ars = "ars_x"
        jaws = grasp_joint_names("ars_x")
        ee.joint_names = [width_joint_name("ars_x"), *jaws.values()]
        ee.position = [s.position(names.width_joint("ars_x"))] + [
            s.position(names.grasp_joint("ars_x", side)) for side in jaws
        ]
        self.ee.publish(ee)

    def close(self) -> None:
        self._stop.set()
        self.thread.join(timeout=10)
        self.scene.close()
        self.node.destroy_node()


def vision_config(**changes) -> dict:
    raw = load_yaml(DEFAULT_CONFIG)
    raw["timeouts"]["frame_s"] = 10.0
    raw.update(changes)
    return raw


class Rig:
    def __init__(self, tmp: Path) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.twin = TwinHost(self.context, tmp)
        config = config_from_dict(vision_config(), "test vision config")
        self.vision = VisionNode(
            config,
            self.twin.scene.mission,
            context=self.context,
            parameter_overrides=[Parameter("use_sim_time", value=True)],
        )
        self.client = Node("vision_test_client", context=self.context)
        self.executor = MultiThreadedExecutor(num_threads=6, context=self.context)
        for n in (self.vision, self.client):
            self.executor.add_node(n)
        self.stop = threading.Event()
        self.spin = threading.Thread(
            target=spin, args=(self.executor, self.context, self.stop.is_set), daemon=True
        )
        self.spin.start()

    def call(self, srv_type, name: str, request):
        client = self.client.create_client(srv_type, name)
        try:
            assert client.wait_for_service(timeout_sec=20.0), f"{name} not served"
            future = client.call_async(request)
            deadline = time.monotonic() + CALL_S
            while not future.done() and time.monotonic() < deadline:
                time.sleep(0.02)
            assert future.done(), f"{name} did not answer in {CALL_S} s"
            return future.result()
        finally:
            self.client.destroy_client(client)

    def close(self) -> None:
        self.stop.set()
        self.spin.join(timeout=10)
        self.executor.shutdown(timeout_sec=5)
        self.twin.close()
        self.vision.destroy_node()
        self.client.destroy_node()
        rclpy.try_shutdown(context=self.context)


@contextlib.contextmanager
def _exact_cameras(rig: Rig):
    """The twin's exact depth and colours, and the node told so, for the checks of the inspection's
    own logic on a strut 0.9 m before a lifter ZED: through the ZED's real depth there, its end
    fittings are out of reach of a certificate (test_a_real_zeds_depth_at_0_9_m_...)."""
    cameras = rig.twin.cameras
    noise = rig.vision.config.raw["depth_noise"]
    realistic, own = cameras.sensors, dict(noise["cameras"])
    cameras.sensors = replace(realistic, realistic=False)
    noise["cameras"] = {}
    try:
        yield
    finally:
        cameras.sensors = realistic
        noise["cameras"] = own


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    r = Rig(tmp_path_factory.mktemp("vision_twin"))
    yield r
    r.close()


AWAY = np.array([5.0, 5.0, -3.0])  # out of every camera's view


def _show(rig: Rig, part: str, camera: str = "zed_1", distance: float = 0.9) -> None:
    """Put ``part`` in front of ``camera`` and every other vertical out of view."""

    def stage(scene: Scene) -> None:
        for p in scene.info.parts.values():
            if p.kind == "vertical" and p.name != part:
                scene.place_part(p.name, AWAY - np.array([0.0, 0.0, p.index]), np.eye(3))
        scene.place_in_view(part, camera, distance)

    rig.twin.do(stage)


def test_vision_says_ready_once_it_has_heard_every_arm(rig):
    """The latched status the CRS waits for before Start: this rig's twin publishes ARS X's arm and
    end effector and the camera mounts; ARS Y's arm and end effector are missing until sent here."""
    from diagnostic_msgs.msg import DiagnosticStatus

    from tlt_common.ros.readiness import LATCHED

    said: list[DiagnosticStatus] = []
    rig.client.create_subscription(DiagnosticStatus, ros_names.VISION_STATUS, said.append, LATCHED)

    def last_word(predicate, what: str) -> DiagnosticStatus:
        deadline = time.monotonic() + 20.0
        while not (said and predicate(said[-1])):
            assert time.monotonic() < deadline, f"{what}: {said[-1:]}"
            time.sleep(0.05)
        return said[-1]

    # ARS Y's six arm joints, its width and two jaws: everything else has been heard of.
    ars_y = f"no joint state yet for {', '.join(arm_joint_names('ars_y')[:3])} and 6 more"
    waiting = last_word(lambda m: m.message == ars_y, "waiting for ARS Y only")
    assert waiting.level == DiagnosticStatus.WARN and waiting.name == "vision"

    arm = rig.client.create_publisher(JointState, ros_names.joint_states_topic("ur_y"), 10)
    ee = rig.client.create_publisher(EndEffectorState, ros_names.state_topic("ee_y"), 10)
    ee_joints = [width_joint_name("ars_y"), *grasp_joint_names("ars_y").values()]
    deadline = time.monotonic() + 20.0
    while not (said and said[-1].level == DiagnosticStatus.OK):
        assert time.monotonic() < deadline, f"never ready: {said[-1:]}"
        arm.publish(JointState(name=arm_joint_names("ars_y"), position=[0.0] * 6))
        ee.publish(EndEffectorState(ars="ars_y", joint_names=ee_joints, position=[0.0] * len(ee_joints)))
        time.sleep(0.1)
    assert said[-1].message == "ready"


def test_a_good_strut_passes_and_defective_ones_fail_with_the_reason(rig):
    with _exact_cameras(rig):
        _a_good_strut_passes_and_defective_ones_fail_with_the_reason(rig)


def _a_good_strut_passes_and_defective_ones_fail_with_the_reason(rig):
    member = "bay1/vertical/x0_y1"
    _show(rig, "vertical_dispenser_x/2")
    tf: list[TFMessage] = []
    markers: list[MarkerArray] = []
    subs = [
        rig.client.create_subscription(TFMessage, ros_names.TF, tf.append, 10),
        rig.client.create_subscription(MarkerArray, ros_names.VISION_MARKERS, markers.append, 10),
    ]
    good = rig.call(
        InspectPart,
        ros_names.VISION_INSPECT_PART,
        InspectPart.Request(member_id=member, part_kind="vertical", camera="zed_left"),
    ).report
    assert good.passed, list(good.reasons)
    assert good.target_id == member and good.header.frame_id == "zed_1_optical"
    classes = sorted(p.object_class for p in good.poses)
    assert classes == ["end_fitting", "end_fitting", "strut_tube"]
    assert all(p.certified for p in good.poses)
    # The certified poses went out on /tf, in the camera's frame, and as markers.
    deadline = time.monotonic() + 10.0
    while not (tf and markers) and time.monotonic() < deadline:
        time.sleep(0.05)
    for sub in subs:
        rig.client.destroy_subscription(sub)
    seen = {t.child_frame_id for m in tf for t in m.transforms if t.header.frame_id == "zed_1_optical"}
    assert {"vision/zed_1/end_fitting_0", "vision/zed_1/end_fitting_1", "vision/zed_1/strut_tube_0"} <= seen
    assert any(m.ns == "vision/zed_1" for a in markers for m in a.markers)

    _show(rig, "vertical_dispenser_x/0")  # built without end fitting b
    missing = rig.call(
        InspectPart,
        ros_names.VISION_INSPECT_PART,
        InspectPart.Request(member_id=member, part_kind="vertical", camera="zed_left"),
    ).report
    assert not missing.passed
    assert any(r.startswith("missing end fitting: 1 of 2 found") for r in missing.reasons), list(
        missing.reasons
    )


def test_inspect_part_allows_for_the_noise_of_the_camera_asked_for(rig):
    """node.yaml ``depth_noise.cameras``: with 1 % noise given for zed_2, a good strut before zed_1
    still passes; given for zed_1 (the twin's depth is exact, the node is told otherwise), its end
    fittings a metre away are out of the noise's reach, and the report says so."""
    member, request = "bay1/vertical/x0_y1", InspectPart.Request
    noise = rig.vision.config.raw["depth_noise"]
    _show(rig, "vertical_dispenser_x/2")
    with _exact_cameras(rig):
        noise["cameras"] = {"zed_2": 0.01}
        other = rig.call(
            InspectPart,
            ros_names.VISION_INSPECT_PART,
            request(member_id=member, part_kind="vertical", camera="zed_left"),
        ).report
        assert other.passed, list(other.reasons)
        noise["cameras"] = {"zed_1": 0.01}
        noisy = rig.call(
            InspectPart,
            ros_names.VISION_INSPECT_PART,
            request(member_id=member, part_kind="vertical", camera="zed_left"),
        ).report
    assert not noisy.passed
    assert any("depth too noisy to certify" in r for r in noisy.reasons), list(noisy.reasons)
    fittings = [p for p in noisy.poses if p.object_class == "end_fitting"]
    assert fittings and not any(p.certified for p in fittings)
    assert all(p.chamfer_threshold > 0.0025 for p in noisy.poses)  # each allowed for the noise


@contextlib.contextmanager
def _segmenting_with(rig: Rig, segmenter):
    """The node segmenting with ``segmenter`` (as Mask R-CNN would, from the twin's labels), and
    a good vertical before zed_1; yields InspectPart's report on it."""
    labels = rig.vision.detector.segmenter
    rig.vision.detector.segmenter = segmenter
    try:
        _show(rig, "vertical_dispenser_x/2")
        with _exact_cameras(rig):
            report = rig.call(
                InspectPart,
                ros_names.VISION_INSPECT_PART,
                InspectPart.Request(member_id="bay1/vertical/x0_y1", part_kind="vertical", camera="zed_1"),
            ).report
        yield report
    finally:
        rig.vision.detector.segmenter = labels


def test_a_real_zeds_depth_at_0_9_m_cannot_certify_end_fittings_and_the_report_says_so(rig):
    """Through the ZED 2i's depth (config/twin/cameras.yaml) and with the node told its noise
    (node.yaml depth_noise.cameras), a good strut 0.9 m away is posed, its tube certified, and its
    end fittings refused as out of the noise's reach: the report says it cannot judge them, never
    a pass on a guess and never a missing fitting that is there."""
    _show(rig, "vertical_dispenser_x/2")
    report = rig.call(
        InspectPart,
        ros_names.VISION_INSPECT_PART,
        InspectPart.Request(member_id="bay1/vertical/x0_y1", part_kind="vertical", camera="zed_1"),
    ).report
    assert not report.passed and report.cannot_judge
    assert any("depth too noisy to certify" in r for r in report.reasons), list(report.reasons)
    assert all(r.startswith("cannot judge the end fitting") for r in report.reasons), list(report.reasons)
    tubes = [p for p in report.poses if p.object_class == "strut_tube"]
    assert tubes and all(p.certified for p in tubes)
    assert not any(p.certified for p in report.poses if p.object_class == "end_fitting")
    # A fitting that is not there is missing however noisy the depth: a verdict, not a doubt.
    _show(rig, "vertical_dispenser_x/0")  # built without end fitting b
    missing = rig.call(
        InspectPart,
        ros_names.VISION_INSPECT_PART,
        InspectPart.Request(member_id="bay1/vertical/x0_y1", part_kind="vertical", camera="zed_1"),
    ).report
    assert not missing.passed and not missing.cannot_judge
    assert any(r.startswith("missing end fitting") for r in missing.reasons), list(missing.reasons)


def test_inspect_part_looks_again_at_doubtful_fittings_other_requests_never_see_them(rig):
    """Fittings scored between second_look_score and min_score (Mask R-CNN's, here the twin's
    labels rescored): InspectPart poses them where the certified tube misses its fittings, and
    the good strut passes; the node's other requests get only detections scoring min_score."""
    labels = rig.vision.detector.segmenter
    seg = rig.vision.config.raw["segmentation"]
    doubtful = (seg["second_look_score"] + seg["min_score"]) / 2

    class Rescored:
        streams = labels.streams

        @staticmethod
        def detect(frame):
            dets = labels.detect(frame)
            return [replace(d, score=doubtful) if d.object_class == "end_fitting" else d for d in dets]

    with _segmenting_with(rig, Rescored()) as good:
        assert good.passed, list(good.reasons)
        assert sorted(p.object_class for p in good.poses) == ["end_fitting", "end_fitting", "strut_tube"]
        detector = rig.vision.detector
        frame = rig.vision.frames.grab("zed_1", detector.streams(), rig.vision.frames.deadline())
        assert not [d for d in detector.detect(frame) if d.object_class == "end_fitting"]
        assert [d for d in detector.detect(frame, doubtful=True) if d.object_class == "end_fitting"]


def test_inspect_part_looks_closer_where_the_frame_showed_no_fitting(rig):
    """A segmenter that finds no end fitting in the whole frame and finds them in the regions it
    is asked to look at again (Mask R-CNN's closer look): InspectPart asks it at the configured
    scale, and the good strut passes on what it finds there."""
    labels = rig.vision.detector.segmenter
    scale = rig.vision.config.raw["segmentation"]["second_look_closer"]["scale"]
    asked = []

    class Closer:
        streams = labels.streams

        @staticmethod
        def detect(frame):
            return [d for d in labels.detect(frame) if d.object_class != "end_fitting"]

        @staticmethod
        def detect_in(frame, region, at):
            asked.append(at)
            x0, y0, x1, y1 = region
            inside = np.zeros(frame.get("depth").shape, dtype=bool)
            inside[y0:y1, x0:x1] = True
            fittings = [d for d in labels.detect(frame) if d.object_class == "end_fitting"]
            return [replace(d, mask=d.mask & inside) for d in fittings if (d.mask & inside).any()]

    with _segmenting_with(rig, Closer()) as good:
        assert good.passed, list(good.reasons)
    assert asked and set(asked) == {scale}


def test_a_part_out_of_view_fails_with_that_reason(rig):
    rig.twin.do(
        lambda s: [
            s.place_part(p.name, AWAY, np.eye(3)) for p in s.info.parts.values() if p.kind == "vertical"
        ]
    )
    report = rig.call(
        InspectPart,
        ros_names.VISION_INSPECT_PART,
        InspectPart.Request(member_id="bay1/vertical/x0_y1", part_kind="vertical", camera="zed_1"),
    ).report
    assert not report.passed and report.reasons[0].startswith("part not in view"), list(report.reasons)


def _look_down_at(scene: Scene, rig: Rig, target: np.ndarray, height: float) -> bool:
    """Put ARS X's arm so that its D405 a looks straight down at ``target`` from ``height``."""
    cam = rig.vision.rig.ee["ars_x/d405_a"]
    optical = pose_matrix(
        target + np.array([0.0, 0.0, height]), np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])
    )
    flange = optical @ np.linalg.inv(cam.optical)
    try:
        q = cam.kinematics.nearest(flange, scene.edu["arms"]["ars_x"]["home"])
    except ValueError:
        return False
    for joint, value in zip(names.arm_joints("ars_x"), q, strict=True):
        scene.set_joint_state(joint, float(value))
    scene.set_joint_state(names.width_joint("ars_x"), 0.0)
    return True


def test_dispenser_tag_is_located_within_millimetres_of_the_twin(rig):
    name = "vertical_dispenser_x"

    def aim(scene: Scene):
        tag = scene.site_position(f"dispenser/{name}/tag")
        assert _look_down_at(scene, rig, tag, 0.45), "no arm pose looks at the tag"
        return scene.body_pose(f"dispenser/{name}")

    pos, rot = rig.twin.do(aim)
    time.sleep(0.5)  # joint states of the new pose reach the vision node
    res = rig.call(
        LocateTag, ros_names.VISION_LOCATE_TAG, LocateTag.Request(dispenser=name, camera="ars_x/d405")
    )
    assert res.found, res.reason
    assert res.tag_id == list(rig.twin.scene.mission.dispensers).index(name)
    assert res.pose.header.frame_id == "world"
    p, q = res.pose.pose.position, res.pose.pose.orientation
    x, y, z, w = q.x, q.y, q.z, q.w
    got = pose_matrix(
        (p.x, p.y, p.z),
        np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        ),
    )
    dp, da = pose_error(got, pose_matrix(pos, rot))
    assert dp < 0.005, f"dispenser located {dp * 1000:.1f} mm from the twin's"
    assert da < np.radians(1.0), f"dispenser turned {np.degrees(da):.2f} deg from the twin's"
    res = rig.call(
        LocateTag,
        ros_names.VISION_LOCATE_TAG,
        LocateTag.Request(dispenser="diagonal_dispenser_y", camera="ars_x/d405"),
    )
    assert not res.found and "not in view" in res.reason


def test_a_cross_frame_held_at_its_place_is_aligned_from_the_d405s(rig):
    """CheckAlignment of a cross frame ARS X holds at its place (the planner's placement
    configuration, the frame seated in the grasp as the twin's grasp seats it)."""
    member = rig.twin.scene.mission.member("bay1/cross_frame")
    cfg = load_scene_config()
    kw = dict(placed=set(), bay=1, carrying="cross_frame")
    free = build_scene(cfg, "ars_x", rig.twin.scene.mission, contact=False, **kw)
    contact = build_scene(cfg, "ars_x", rig.twin.scene.mission, contact=True, **kw)
    target = placement_targets(cfg, rig.twin.scene.mission, member, "ars_x")[0]
    _, q = reach_target(free, contact, target, cfg.home("ars_x"), cfg.planning["dense_check_resolution"])

    def hold(scene: Scene) -> None:
        for joint, value in zip(names.arm_joints("ars_x"), q, strict=True):
            scene.set_joint_state(joint, float(value))
        scene.set_joint_state(names.width_joint("ars_x"), 0.0)
        mujoco.mj_forward(scene.model, scene.data)
        part = scene.part(scene.next_part("cross_frame_dispenser"))
        centre, axis = scene.assembly.grasp_line("ars_x")
        tool = cfg.kinematics("ars_x").forward(q)
        y = tool[:3, 1] - (tool[:3, 1] @ axis) * axis
        y /= np.linalg.norm(y)
        scene.place_part(
            part.name, centre - axis * part.length / 2, np.column_stack([axis, y, np.cross(axis, y)])
        )

    rig.twin.do(hold)
    _wait_until_heard(rig, q)
    res = rig.call(
        CheckAlignment,
        ros_names.VISION_CHECK_ALIGNMENT,
        CheckAlignment.Request(member_id=member.id, camera="ars_x/d405"),
    )
    assert res.aligned, res.reason
    assert res.position_error < 0.003 and res.angle_error < np.radians(0.5)
    assert res.pose.certified and res.pose.header.frame_id == "world"
    assert res.pose.keypoint_groups_visible == 2  # a corner joint in each D405
    p = res.pose.pose.position
    assert np.linalg.norm([p.x, p.y, p.z] - target.pose[:3, 3]) < 0.003  # held where the ARS aims


def _wait_until_heard(rig: Rig, q: np.ndarray) -> None:
    """Until the vision node's latest ARS X joint states are ``q`` (a fixed wait was too short on a
    loaded CI machine, and the D405s were placed from the old pose)."""

    def heard() -> bool:
        try:
            now = rig.vision.rig.joints.latest(arm_joint_names("ars_x"))
            return np.allclose(now, q, atol=1e-3)
        except FrameUnavailable:  # none heard yet
            return False

    deadline = time.monotonic() + 20.0
    while not heard():
        assert time.monotonic() < deadline, "the vision node never heard the new arm pose"
        time.sleep(0.05)


def test_a_rivet_taken_at_the_feeder_is_seen_in_the_gun_and_the_feeders_are_not_posed(rig, monkeypatch):
    """InspectPart of a rivet gun that took a rivet, as the ARS asks it (after Withdraw Gun): the
    D405 beside the gun sees the feeder's tray full of rivets too; only those near the muzzle are
    posed."""
    mission = rig.twin.scene.mission
    feeder = next(n for n, d in mission.dispensers.items() if d.part_kind == "rivet" and n.endswith("_x"))
    cfg = load_scene_config()
    kw = dict(placed=set(), bay=1, carrying=None)
    free = build_scene(cfg, "ars_x", mission, contact=False, **kw)
    contact = build_scene(cfg, "ars_x", mission, contact=True, **kw)
    resolution = cfg.planning["dense_check_resolution"]
    for target in dispenser_targets(cfg, mission, feeder, "ars_x"):  # the gun from any side
        try:
            q_out, q = reach_target(free, contact, target, cfg.home("ars_x"), resolution)
            break
        except TargetUnreachable:
            continue
    else:
        pytest.fail(f"the planner reaches {feeder} from no side")

    def take_rivet(scene: Scene) -> bool:
        scene.pose_arm("ars_x", q)
        scene.set_joint_state(names.width_joint("ars_x"), 0.0)
        mujoco.mj_forward(scene.model, scene.data)
        loaded = scene.load_rivet("ars_x", "a")
        scene.pose_arm("ars_x", q_out)
        return loaded

    assert rig.twin.do(take_rivet)
    _wait_until_heard(rig, q_out)
    request = InspectPart.Request(member_id="ars_x/rivet_gun_0", part_kind="rivet", camera="ars_x/d405")
    report = rig.call(InspectPart, ros_names.VISION_INSPECT_PART, request).report
    assert report.passed, list(report.reasons)
    assert [p.object_class for p in report.poses] == ["rivet"] and report.poses[0].certified
    # Mask R-CNN's view of a rivet cut by the frame's border: split in two, each half scored
    # under min_score. The halves at the muzzle are joined and posed as one rivet.
    labels = rig.vision.detector.segmenter
    low = rig.vision.config.raw["segmentation"]["min_score"] / 2

    class Split:
        streams = labels.streams

        @staticmethod
        def detect(frame):
            halves = []
            for d in labels.detect(frame):
                cols = np.nonzero(d.mask.any(axis=0))[0]
                middle = (cols.min() + cols.max() + 1) // 2
                for keep in (np.arange(d.mask.shape[1]) < middle, np.arange(d.mask.shape[1]) >= middle):
                    halves.append(replace(d, mask=d.mask & keep[None, :], score=low))
            return halves

    monkeypatch.setattr(rig.vision.detector, "segmenter", Split())
    split = rig.call(InspectPart, ros_names.VISION_INSPECT_PART, request).report
    assert split.passed, list(split.reasons)
    assert [p.object_class for p in split.poses] == ["rivet"] and split.poses[0].certified
    monkeypatch.setattr(rig.vision.detector, "segmenter", labels)
    # With the muzzle configured 10 cm further out, the rivet in the gun is one seen elsewhere:
    # not posed, and the report says so.
    cam = rig.vision.rig.ee["ars_x/d405_a"]
    moved = replace(cam, gun_position=cam.gun_position + np.array([0.0, 0.0, 0.1]))
    monkeypatch.setitem(rig.vision.rig.ee, "ars_x/d405_a", moved)
    report = rig.call(InspectPart, ros_names.VISION_INSPECT_PART, request).report
    assert not report.passed and not report.poses
    assert any("seen farther from the muzzle, not posed" in r for r in report.reasons), list(report.reasons)


def test_no_frame_in_time_answers_with_the_reason(rig):
    rig.twin.rendering = False  # a stalled twin: nothing is rendered
    try:
        t0 = time.monotonic()
        report = rig.call(
            InspectPart,
            ros_names.VISION_INSPECT_PART,
            InspectPart.Request(member_id="bay1/vertical/x0_y1", part_kind="vertical", camera="zed_1"),
        ).report
        waited = time.monotonic() - t0
    finally:
        rig.twin.rendering = True
    assert not report.passed
    assert report.reasons[0].startswith("no camera frame from zed_1 within 10.0 s"), list(report.reasons)
    assert waited < CALL_S
    report = rig.call(
        InspectPart,
        ros_names.VISION_INSPECT_PART,
        InspectPart.Request(member_id="x", part_kind="vertical", camera="zed_9"),
    ).report
    assert not report.passed and report.reasons[0].startswith("unknown camera 'zed_9'")


def test_segmentation_is_chosen_on_the_command_line_and_checked_as_the_file_would_be(tmp_path, capsys):
    """``--segmentation`` (a launch set's TLT_SEGMENTATION) overrides the file's source; empty
    keeps it; an unknown source, or Mask R-CNN without weights, is refused naming what is wrong."""
    config = load_config(DEFAULT_CONFIG)
    assert config.with_segmentation("mask_rcnn").raw["segmentation"]["source"] == "mask_rcnn"
    assert config.raw["segmentation"]["source"] == load_config(DEFAULT_CONFIG).raw["segmentation"]["source"]
    no_weights = vision_config()
    no_weights["segmentation"].update(source="twin_labels", weights="")
    path = tmp_path / "node.yaml"
    path.write_text(__import__("yaml").safe_dump(no_weights))
    with pytest.raises(ConfigError, match=r"segmentation\.weights: mask_rcnn needs a weights file"):
        load_config(path).with_segmentation("mask_rcnn")
    assert main(["--config", str(path), "--segmentation", "mask_rcnn"]) == 2
    assert "--segmentation mask_rcnn" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--segmentation", "labels"])
    assert "'labels' is not one of twin_labels, mask_rcnn" in capsys.readouterr().err


def test_bad_configuration_and_weights_are_refused_naming_file_and_key(tmp_path, capsys):
    bad = vision_config(part_depth_range=[2.0, 0.5])
    path = tmp_path / "bad.yaml"
    path.write_text(__import__("yaml").safe_dump(bad))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "part_depth_range" in err
    wrong = vision_config()
    wrong["segmentation"]["source"] = "labels"
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "segmentation.source" in err and "'labels'" in err
    wrong = vision_config()
    wrong["segmentation"].update(min_score=0.3, second_look_score=0.4)
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "segmentation.second_look_score" in err and "above min_score 0.3" in err
    wrong = vision_config()
    wrong["segmentation"]["depth_split"] = {
        "jump": -0.02,
        "jump_per_m": 0.01,
        "min_area": 30,
        "full_score_area": 200,
    }
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "segmentation.depth_split.jump" in err and "-0.02" in err
    wrong["segmentation"]["depth_split"].update(jump=0.02, width_band=[1.3, 0.6])
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "segmentation.depth_split.width_band" in err and "low < high" in err
    wrong["segmentation"]["depth_split"].update(width_band=[0.6, 1.3], bend_tolerance=0.2)
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "segmentation.depth_split.bend_tolerance" in err and "0.2" in err
    wrong["segmentation"]["depth_split"].update(bend_tolerance=2.0)
    wrong["depth_noise"] = {"fraction": 1.0}
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    assert "depth_noise.fraction" in capsys.readouterr().err
    wrong["depth_noise"] = {"fraction": 0.01, "window": 4}
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "depth_noise.window" in err and "must be odd" in err
    wrong = vision_config()
    wrong["segmentation"]["semantic_trim"] = {"classes": ["fitting"], "above": 0.3}
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "segmentation.semantic_trim.classes" in err and "'fitting'" in err
    wrong["segmentation"]["semantic_trim"] = {"classes": [], "above": 0.3, "cores": ["joint"]}
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "segmentation.semantic_trim.cores" in err and "'joint'" in err
    wrong = vision_config()
    wrong["segmentation"]["exclusive_overlaps"] = {"classes": ["end_fitting"], "duplicate": 1.5}
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "segmentation.exclusive_overlaps.duplicate" in err and "1.5" in err
    wrong = vision_config()
    wrong["segmentation"]["semantic_background_weight"] = 0  # no pixel would be background
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    assert "segmentation.semantic_background_weight" in capsys.readouterr().err
    wrong = vision_config()
    wrong["segmentation"]["semantic_vote"] = "yes"
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    assert "segmentation.semantic_vote" in capsys.readouterr().err
    wrong = vision_config()
    wrong["axial_slide"] = {"classes": ["corner_joint"]}  # a cube has no axis to slide along
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "axial_slide.classes" in err and "corner_joint" in err
    wrong = vision_config()
    wrong["parting"] = {"classes": ["cross_frame"]}  # a frame's sides are pieces of one part
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "parting.classes" in err and "cross_frame" in err
    wrong["parting"] = {"classes": ["end_fitting"], "in_mask": 1.5}
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    assert "parting.in_mask" in capsys.readouterr().err
    wrong = vision_config()
    wrong["detached"] = {"largest_only": ["strut_tube"]}  # a tube crossed in front is two pieces of it
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "detached.largest_only" in err and "strut_tube" in err
    for links, named in (({"strut_tube": 0.01}, "compact part classes"), ({"rivet": 0.0}, "0.0")):
        wrong = vision_config()
        wrong["detached"] = {"links": links}
        path.write_text(__import__("yaml").safe_dump(wrong))
        assert main(["--config", str(path)]) == 2
        err = capsys.readouterr().err
        assert "detached.links" in err and named in err
    wrong = vision_config()
    wrong["corrector"]["turned_starts"] = ["strut_tube"]  # a tube turned end-on is no start
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "corrector.turned_starts" in err and "strut_tube" in err
    wrong = vision_config()
    wrong["corrector"]["tilted_starts"] = {"classes": ["corner_joint"], "angle_deg": 0.0}
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "corrector.tilted_starts.angle_deg" in err
    wrong = vision_config()
    wrong["corrector"]["trim"] = {"classes": ["end_fitting"], "fraction": 0.9}  # the fit left to a tenth
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "corrector.trim.fraction" in err and "0.9" in err
    wrong = vision_config()
    wrong["corrector"]["points"] = -1
    path.write_text(__import__("yaml").safe_dump(wrong))
    assert main(["--config", str(path)]) == 2
    assert "corrector.points" in capsys.readouterr().err
    missing = vision_config()
    missing["detectors"]["rivet"] = str(tmp_path / "none.pt")
    path.write_text(__import__("yaml").safe_dump(missing))
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "none.pt" in err and "weights file not found" in err


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_process_exits_cleanly_on_a_signal(sig, wait_for_service):
    """As a launcher stops it: the spin loop ends and the node is destroyed with rclpy's context
    still valid (rclpy's own handler would shut it down under a pose being computed)."""
    # Its own service name: in this session other vision nodes came and went, and the graph may
    # still list theirs (a clean-clone run once signalled the process before it had started).
    service = f"/signal_test_{sig}_{time.monotonic_ns()}/inspect_part"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "tlt_vision.node",
            "--ros-args",
            "-r",
            f"{ros_names.VISION_INSPECT_PART}:={service}",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        wait_for_service(proc, InspectPart, service)
        proc.send_signal(sig)
        assert proc.wait(timeout=20) == 0, proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_an_arms_end_effector_is_taken_out_of_the_depth_where_the_twin_has_it(rig):
    """InspectPart poses the part on a depth without the arms' own EE bodies (node.yaml
    ``ee_self_filter``), placed by the published joint states: the pixels the node drops are the
    ones the twin's own EE boxes and jaw capsules hold."""
    from tlt_tools.vision_training.twin_renderer import inspection_joints

    joints = inspection_joints()["ars_x"]
    boxes = [f"ars_x/{name}" for name in rig.vision.config.raw["ee_self_filter"]["boxes"]]
    margin = rig.vision.config.raw["ee_self_filter"]["margin"]

    def present_arm(scene: Scene) -> None:
        scene.command_positions(names.arm_joints("ars_x"), list(joints))
        scene.pose_arm("ars_x", joints)

    rig.twin.do(present_arm)
    time.sleep(1.0)  # joint states and frames of the arm standing there
    node = rig.vision
    frame = node.frames.grab("zed_2", node.detector.streams(), node.frames.deadline())  # zed_2 faces ARS X
    depth = frame.get("depth")
    dropped = (depth > 0) & (node.part_handler.without_own_ee(frame) == 0)

    def in_the_twins_boxes(scene: Scene) -> np.ndarray:
        position, rotation = scene.camera_pose("zed_2")
        k = frame.intrinsics
        v, u = np.mgrid[0 : depth.shape[0], 0 : depth.shape[1]]
        local = np.stack([(u - k.cx) * depth / k.fx, (v - k.cy) * depth / k.fy, depth], -1)
        world = local.reshape(-1, 3) @ rotation.T + position
        inside = np.zeros(len(world), dtype=bool)
        for name in boxes:
            g = scene.model.geom(name).id
            box = (world - scene.data.geom_xpos[g]) @ scene.data.geom_xmat[g].reshape(3, 3)
            inside |= np.all(np.abs(box) <= scene.model.geom_size[g] + margin, axis=1)
        for side in ("a", "b"):
            g = scene.model.body_geomadr[scene.model.body(f"ars_x/jaw_{side}").id]
            radius, half = scene.model.geom_size[g][:2]
            axis = scene.data.geom_xmat[g].reshape(3, 3)[:, 2]
            along = np.clip((world - scene.data.geom_xpos[g]) @ axis, -half, half)
            nearest = scene.data.geom_xpos[g] + along[:, None] * axis
            inside |= np.linalg.norm(world - nearest, axis=1) <= radius + margin
        return inside.reshape(depth.shape) & (depth > 0)

    truth = rig.twin.do(in_the_twins_boxes)
    assert truth.sum() > 300, truth.sum()  # the EE is in view
    iou = (dropped & truth).sum() / (dropped | truth).sum()
    assert iou > 0.9, (iou, dropped.sum(), truth.sum())
