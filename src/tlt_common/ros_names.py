"""The names of the system's ROS topics, services and actions, in one place.

Every agent builds the names it publishes, serves or calls from these functions, so the CRS, the
ARSs, vision, the drivers and the tests cannot drift apart. Names are absolute: a driver node for
component ``lifter`` publishes ``/lifter/state`` whatever its node name or namespace.
"""

from __future__ import annotations

ARS_AGENTS = ("ars_x", "ars_y")

# --- driver components (paper §V.B) ---------------------------------------------------------------
LIFTER = "lifter"
TOP_GRIPPERS = "top_grippers"
ACTIVE_GRIPPERS = "active_grippers"
CAMERA_MOUNTS = "camera_mounts"


def ee(ars: str) -> str:
    """End-effector component of an ARS: ``ars_x`` -> ``ee_x``."""
    return "ee_" + ars.removeprefix("ars_")


def ur(ars: str) -> str:
    """UR arm component of an ARS: ``ars_x`` -> ``ur_x``."""
    return "ur_" + ars.removeprefix("ars_")


def state_topic(component: str) -> str:
    """LifterState, GripperState or EndEffectorState of a component."""
    return f"/{component}/state"


def joint_states_topic(component: str) -> str:
    """sensor_msgs/JointState of a component's joints."""
    return f"/{component}/joint_states"


def hardware_status_topic(component: str) -> str:
    """tlt_interfaces/HardwareStatus of a component's hardware interface."""
    return f"/{component}/hardware_status"


def trajectory_action(component: str) -> str:
    """FollowJointTrajectory of a component's trajectory-controlled joints."""
    return f"/{component}/follow_joint_trajectory"


def executed_trajectories_topic(component: str) -> str:
    """tlt_interfaces/ExecutedTrajectory: each of a component's trajectory goals, once it ended."""
    return f"/{component}/executed_trajectories"


def position_command_topic(component: str) -> str:
    """std_msgs/Float64MultiArray for a component's group-position-controlled joints."""
    return f"/{component}/position_command"


LIFTER_SET_MODE = "/lifter/set_mode"


def ur_unlock_service(ur_component: str) -> str:
    """std_srvs/Trigger: release a UR protective stop through the dashboard."""
    return f"/{ur_component}/unlock_protective_stop"


def ee_calibrate_service(ee_component: str) -> str:
    """std_srvs/Trigger: seek the EE width joint's limit switch and zero it."""
    return f"/{ee_component}/calibrate"


def ee_calibrate_when_released_service(ee_component: str) -> str:
    """std_srvs/Trigger: seek the EE width joint's limit switch once the grippers hold no part (an
    operator's choice while the driver waits with a part held after its width servo lost its count)."""
    return f"/{ee_component}/calibrate_when_released"


def ee_rivet_gun_service(ee_component: str) -> str:
    """SetActuatorState: drive one of the EE's rivet-gun GPIO outputs."""
    return f"/{ee_component}/set_rivet_gun"


# --- agents (paper §IV, §V.C.1) --------------------------------------------------------------------
ARS_ACTIONS = ("add_cross_frame", "add_member", "affix_member", "foundation_rivet")


def ars_action(ars: str, request: str) -> str:
    """An ARS's action server for one CRS request, e.g. ``/ars_x/add_member``."""
    if request not in ARS_ACTIONS:
        raise ValueError(f"unknown ARS request {request!r} (known: {', '.join(ARS_ACTIONS)})")
    return f"/{ars}/{request}"


def ground_command_service(agent: str) -> str:
    """GroundCommand forwarded by the CRS to an ARS."""
    return f"/{agent}/ground_command"


def set_blackboard_service(agent: str) -> str:
    """SetBlackboardValue of one agent: the ground's writes to its writable keys."""
    return f"/{agent}/set_blackboard_value"


def tree_status_topic(agent: str) -> str:
    """TreeStatus of an agent's behaviour tree."""
    return f"/{agent}/tree_status"


def tree_definition_topic(agent: str) -> str:
    """The definition of each shape of an agent's behaviour tree (std_msgs/String, JSON document
    of tlt_common.bt.shape_definition; transient local)."""
    return f"/{agent}/tree_definition"


CRS_INSPECT_PART = "/crs/inspect_part"  # served by the CRS for the ARSs (it forwards to vision)
CRS_SET_BLACKBOARD = "/crs/set_blackboard_value"
CRS_MISSION_PROGRESS = "/crs/mission_progress"
EVENTS = "/events"

# --- vision (paper §V.E) ---------------------------------------------------------------------------
VISION_INSPECT_PART = "/vision/inspect_part"
VISION_INSPECT_BAY = "/vision/inspect_bay"
VISION_CHECK_ALIGNMENT = "/vision/check_alignment"
VISION_LOCATE_TAG = "/vision/locate_tag"
VISION_VERIFY_JOINT = "/vision/verify_joint"
# diagnostic_msgs/DiagnosticStatus, latched (tlt_common.ros.readiness): OK once vision can place
# every camera (it has heard the joint states of both arms and the camera mounts), else why not.
VISION_STATUS = "/vision/status"
# visualization_msgs/MarkerArray: each certified pose a request found, in its camera's frame
# (docs/live-view.md).
VISION_MARKERS = "/vision/markers"

# --- live view (docs/live-view.md) -----------------------------------------------------------------
# tf2_msgs/TFMessage: transforms that move, and the fixed ones (latched), as every ROS 2 tool reads them.
TF = "/tf"
TF_STATIC = "/tf_static"
# std_msgs/String, latched: the EDU's URDF.
ROBOT_DESCRIPTION = "/robot_description"
