"""Behaviours that talk to ROS without ever blocking a tick (paper §V.C.1), and their helpers.

Each behaviour sends its request asynchronously, polls the returned futures in ``update()`` and
cancels what it started in ``terminate()`` when a parent pre-empts it (new status INVALID). The
node they use must be spun by someone else (an executor in a thread, or ``spin_once`` between
ticks): a behaviour never spins, sleeps or waits.

``clock``: seconds on the node's clock (ROS time), on which every time limit is measured.
``clients``: one action or service client per node and server name.
``remote_call``: what a goal and a service call share (readiness, wait, blackboard answer).
``action_goal``: :class:`ActionGoal`, one goal followed to its result.
``service_call``: :class:`ServiceCall`, one request and its response.
``topics``: :class:`TopicCache`, :class:`TopicCondition`, :class:`TopicData`.
``tree_status``: :class:`TreeStatusPublisher`, a tree's status on a topic.

The names below are the package's interface: import them from ``tlt_common.bt.ros``.
"""

from tlt_common.bt.ros.action_goal import ActionGoal, default_feedback_text
from tlt_common.bt.ros.clients import shared_action_client, shared_service_client
from tlt_common.bt.ros.clock import Clock, RosSeconds, node_clock
from tlt_common.bt.ros.remote_call import RemoteCall, default_result_ok
from tlt_common.bt.ros.service_call import ServiceCall
from tlt_common.bt.ros.topics import TopicCache, TopicCondition, TopicData
from tlt_common.bt.ros.tree_status import TreeStatusPublisher

__all__ = [
    "ActionGoal",
    "Clock",
    "RemoteCall",
    "RosSeconds",
    "ServiceCall",
    "TopicCache",
    "TopicCondition",
    "TopicData",
    "TreeStatusPublisher",
    "default_feedback_text",
    "default_result_ok",
    "node_clock",
    "shared_action_client",
    "shared_service_client",
]
