"""Everything the ARS behaviours share: the node, the configuration, the mission state, the sensor
caches, the planner, and the state of the request being carried out.

One :class:`ArsContext` per ARS process. Behaviours read sensors through it (``arm_q`` from the
UR driver's JointState, ``ee_state`` from the EE driver's EndEffectorState, the other arm's
configuration for the collision scene) and keep the request's working data in
:class:`~tlt_ars.request_data.RequestData` (which part is held, the target chosen for an approach,
the dispenser pose found on its tag, the parts discarded), which the tree resets for each request.

A request can end after its member was set (placed, affixed, riveted) without the CRS hearing of
it: a Release or Retreat that a lost link or a protective stop failed, the ARS killed before the
request ended, or the result lost on a broken link. The CRS, which has not recorded the member,
sends the same request again, and :meth:`ArsContext.check_request` lets that one through (the
mission state alone would refuse it as already placed) so that the ARS can finish it: let go and
retreat from where the arm stands, and report success. So the last request that set its member is
kept as the context's ``unfinished`` request until another request begins. So is one that began
the step that sets its member and never recorded it (``RequestData.setting``: the ARS killed while
the gun fired or while a cross frame was let go of, the gun's output never seen off): its member
may be set, so sent again, the request does that step again from where the arm still stands and
finishes (:meth:`tlt_ars.subtrees.SubtreeBuilder.finish_in_doubt`).

A request can also end with a part in the gripper (a motion or a measurement failed on the way to
the tower): the next request starts holding it (``RequestData.holding``, so the collision scene
has it) and discards it first (:meth:`tlt_ars.subtrees.SubtreeBuilder.branch`). Likewise with a
rivet in the gun (``RequestData.rivet_in_gun``): the next request looks for it before loading one
(:meth:`tlt_ars.subtrees.SubtreeBuilder.load_rivet`).

Both are kept in the state file when there is one (:class:`~tlt_ars.request_data.RequestFile`,
brought up to date by :meth:`ArsContext.keep`), where a restarted ARS finds them.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from tlt_interfaces.msg import EndEffectorState, HardwareStatus

from tlt_ars.config import ArsConfig
from tlt_ars.mission_state import MissionState, Request
from tlt_ars.planning.world import SceneConfig, Width
from tlt_ars.request_data import RequestData, RequestFile
from tlt_common import ros_names
from tlt_common.bt.ros import Clock, TopicCache, node_clock
from tlt_common.mission.schema import Member, Mission
from tlt_common.ros.readiness import ReadinessWatch

# Above this the width slide is taken to be moving (the servo's 15 mm/s drive, not its jitter).
WIDTH_MOVING_M_S = 0.002


class ArsContext:
    """Shared state of one ARS; see the module docstring."""

    def __init__(
        self,
        node: Node,
        config: ArsConfig,
        mission: Mission,
        scene: SceneConfig,
        *,
        clock: Clock | None = None,
        request_file: RequestFile | None = None,
    ) -> None:
        self.node = node
        self.config = config
        self.mission = mission
        self.scene = scene
        self.ars = config.ars
        self.other_ars = next((a for a in ros_names.ARS_AGENTS if a != self.ars), None)
        self.state = MissionState(mission, self.ars)
        self.clock = clock or node_clock(node)
        self.cache = TopicCache(node, self.clock)
        self.joint_topic = ros_names.joint_states_topic(ros_names.ur(self.ars))
        self.other_joint_topic = (
            ros_names.joint_states_topic(ros_names.ur(self.other_ars)) if self.other_ars else None
        )
        self.ee_topic = ros_names.state_topic(ros_names.ee(self.ars))
        self.arm_status_topic = ros_names.hardware_status_topic(ros_names.ur(self.ars))
        self.cache.watch(self.joint_topic, JointState)
        self.cache.watch(self.arm_status_topic, HardwareStatus)
        if self.other_joint_topic:
            self.cache.watch(self.other_joint_topic, JointState)
        self.cache.watch(self.ee_topic, EndEffectorState)
        # Vision's word on its readiness: a question to vision lost with a restarted vision process
        # is asked again once it says ready (tlt_ars.behaviours.vision).
        self.vision_status = ReadinessWatch(node, ros_names.VISION_STATUS)
        # One width-command publisher for every Set Width of every branch the ARS builds.
        self.width_publisher = node.create_publisher(
            Float64MultiArray, ros_names.position_command_topic(ros_names.ee(self.ars)), 10
        )
        # The width last commanded (Set Width): a motion planned before the slide stands there is
        # checked over the rest of the slide's move (planning_width).
        self.width_target: float | None = None
        # Planning is CPU work of up to a second: it runs here, never in the tick.
        self.planning_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"{self.ars}-planner")
        # RequestFileError propagates: the ARS does not start on a state file it cannot read.
        self.request_file = request_file
        kept = request_file.load() if request_file is not None else None
        self.data = kept or RequestData()
        self.unfinished: RequestData | None = kept if kept is not None and kept.unfinished() else None
        if kept is not None and kept.recorded:
            self._mark(kept.member, kept.recorded)

    # ----- sensors -----
    def arm_q(self, max_age: float = 1.0) -> np.ndarray | None:
        """This arm's joint positions in planning order, or None without a fresh JointState."""
        return self._joints(self.joint_topic, self.config.arm["joint_names"], max_age)

    def arm_velocity(self, max_age: float = 1.0) -> np.ndarray | None:
        entry = self.cache.latest(self.joint_topic)
        if entry is None or self.clock() - entry[1] > max_age:
            return None
        msg = entry[0]
        if len(msg.velocity) != len(msg.name):
            return None
        by_name = dict(zip(msg.name, msg.velocity, strict=True))
        try:
            return np.array([by_name[n] for n in self.config.arm["joint_names"]], dtype=float)
        except KeyError:
            return None

    def arm_down(self) -> str | None:
        """Why the UR driver's last HardwareStatus says the arm is not active (link lost, in
        ERROR while it reconnects), or None when active or not heard of yet."""
        entry = self.cache.latest(self.arm_status_topic)
        if entry is None or entry[0].lifecycle_state == HardwareStatus.LIFECYCLE_ACTIVE:
            return None
        return entry[0].fault or f"lifecycle state {entry[0].lifecycle_state}"

    def other_arm_q(self, max_age: float = 1.0) -> np.ndarray | None:
        """The other arm's configuration (for the collision scene), or None when not known."""
        if not self.other_joint_topic:
            return None
        names = [
            n.replace(ros_names.ur(self.ars), ros_names.ur(self.other_ars))
            for n in self.config.arm["joint_names"]
        ]
        return self._joints(self.other_joint_topic, names, max_age)

    def _joints(self, topic: str, names: list[str], max_age: float) -> np.ndarray | None:
        entry = self.cache.latest(topic)
        if entry is None or self.clock() - entry[1] > max_age:
            return None
        by_name = dict(zip(entry[0].name, entry[0].position, strict=False))
        try:
            return np.array([by_name[n] for n in names], dtype=float)
        except KeyError:
            return None

    def ee_state(self, max_age: float = 1.0) -> tuple[EndEffectorState, float] | None:
        """(EndEffectorState, arrival time) when fresh, else None."""
        entry = self.cache.latest(self.ee_topic)
        if entry is None or self.clock() - entry[1] > max_age:
            return None
        return entry

    def _width_joint(self, max_age: float) -> tuple[float, float] | None:
        """(position m, velocity m/s) of the EE width joint, or None without a fresh
        EndEffectorState that says it is calibrated."""
        entry = self.ee_state(max_age)
        if entry is None or not entry[0].calibrated:
            return None
        names = list(entry[0].joint_names)
        joint = self.config.ee["width_joint"]
        if joint not in names:
            return None
        i = names.index(joint)
        velocity = entry[0].velocity[i] if i < len(entry[0].velocity) else 0.0
        return float(entry[0].position[i]), float(velocity)

    def ee_width(self, max_age: float = 1.0) -> float | None:
        """Where the EE width joint stands (m), or None without a fresh EndEffectorState that says
        the joint is calibrated (after a reboot its multi-turn servo reads a wrong width)."""
        joint = self._width_joint(max_age)
        return None if joint is None else joint[0]

    def planning_width(self, max_age: float = 1.0) -> Width | None:
        """Where the width slide stands for a motion plan: its width, or (width, commanded width)
        while it moves; None without a calibrated width (:meth:`ee_width`)."""
        joint = self._width_joint(max_age)
        if joint is None:
            return None
        width, velocity = joint
        target = self.width_target
        if target is None and abs(velocity) > WIDTH_MOVING_M_S:
            # An ARS restarted while the slide moves (a Retract Width is not waited for) does not
            # know the command: the slide may go as far as the widest or narrowest it is sent to.
            widths = self.config.ee["width"].values()
            target = float(max(widths) if velocity > 0 else min(widths))
        if target is None or abs(target - width) <= self.config.ee["width_tolerance"]:
            return width
        return (width, target)

    # ----- request -----
    def finishes(self, request: Request) -> bool:
        """Whether ``request`` repeats the unfinished request (same request and member)."""
        left = self.unfinished.request if self.unfinished is not None else None
        same = (request.request, request.member_id, request.joint)
        return left is not None and (left.request, left.member_id, left.joint) == same

    def check_request(self, request: Request) -> str | None:
        """``None`` when ``request`` may run (it may finish the unfinished one), else why not."""
        if self.finishes(request):
            return None
        left = self.unfinished
        if left is not None and left.holding is not None:
            how = left.recorded or "perhaps set (the step that sets it began)"
            return (
                f"the gripper still holds '{left.member.id}', {how} in the tower: only"
                f" {left.request.request} for it, sent again, lets go of it"
            )
        return self.state.check_request(request)

    def begin(self, request: Request) -> bool:
        """Start the working data of ``request``; True when it finishes the unfinished request,
        whose data (the targets its approaches chose) it carries on with. Any other request drops
        the unfinished one, and starts with the part and the rivet an earlier one left in the
        gripper and the gun.
        ``OSError`` when the state file cannot be brought up to date."""
        finishing = self.finishes(request)
        if finishing:
            self.data = self.unfinished
            self.data.request, self.data.discarded_from = request, []  # reported with the failure
        else:
            held = self.data
            self.data = RequestData(
                request=request, member=self.state.member(request.member_id),
                holding=held.holding, dispenser=held.dispenser, rivet_in_gun=held.rivet_in_gun,
            )  # fmt: skip
        self.unfinished = None
        if (why := self.keep()) is not None:
            raise OSError(why)
        return finishing

    def record(self, what: str) -> str | None:
        """The request has set its member: ``what`` is placed, affixed or riveted. Marked in the
        mission state and kept in the state file before anything else moves; returns why the
        file could not be written, if it could not (the member stays known set in memory)."""
        member = self.data.member
        if member is None:
            raise ValueError("no member in this request")
        self._mark(member, what)
        self.data.recorded = what
        self.data.setting, self.data.setting_q = "", None
        return self.keep()

    def keep(self) -> str | None:
        """Bring the state file up to date with the request's data: kept while it holds a part or
        a rivet, or has set its member, removed otherwise. Returns why it could not be written, or
        None."""
        if self.request_file is None:
            return None
        try:
            if self.data.worth_keeping():
                self.request_file.save(self.data)
            else:
                self.request_file.clear()
        except OSError as exc:
            return f"the state file {self.request_file.path} cannot be written: {exc.strerror or exc}"
        return None

    def _mark(self, member: Member, what: str) -> None:
        {"placed": self.state.mark_placed, "affixed": self.state.mark_affixed,
         "riveted": self.state.mark_riveted}[what](member.id)  # fmt: skip

    def end(self, request: Request) -> None:
        """``request`` ended: kept as unfinished when it set its member (or may have), whether it
        then failed or its success may not reach the CRS."""
        if self.data.unfinished() and self.data.request == request:
            self.unfinished = self.data

    def close(self) -> None:
        self.planning_pool.shutdown(wait=False, cancel_futures=True)


__all__ = ["ArsContext"]
