"""The Python message class of a ROS type name, which rclpy needs even to subscribe ``raw``.

``pkg/msg/Name`` is ``pkg.msg.Name``. Types derived from services and actions live inside their
parent class: ``pkg/action/X_FeedbackMessage`` is ``pkg.action.X.Impl.FeedbackMessage`` (the
type of an action's ``_action/feedback`` topic), ``pkg/action/X_Goal`` is ``pkg.action.X.Goal``,
``pkg/srv/X_Event`` is ``pkg.srv.X.Event`` (service introspection topics).

A type that cannot be imported raises :class:`UnknownMessageType` with the reason.
"""

from __future__ import annotations

import importlib

from tlt_common.recording.message_definitions import DefinitionNotFound, split_type_name

_ACTION_PARTS = ("Goal", "Result", "Feedback")
_ACTION_IMPL_PARTS = ("FeedbackMessage", "GoalRequestService", "CancelGoalService", "GetResultService")
_SERVICE_PARTS = ("Request", "Response", "Event")


class UnknownMessageType(LookupError):
    """The message class of a type name cannot be imported."""


def import_message_type(type_name: str) -> type:
    """Import and return the message class of ``type_name`` (e.g. ``std_msgs/msg/String``)."""
    try:
        package, kind, name = split_type_name(type_name)
    except DefinitionNotFound as exc:
        raise UnknownMessageType(str(exc)) from None
    try:
        module = importlib.import_module(f"{package}.{kind}")
    except ImportError as exc:
        raise UnknownMessageType(f"{type_name}: cannot import {package}.{kind}: {exc}") from None
    cls = getattr(module, name, None)
    if cls is None and "_" in name:
        base, _, part = name.rpartition("_")
        parent = getattr(module, base, None)
        if parent is not None:
            if kind == "action" and part in _ACTION_IMPL_PARTS:
                cls = getattr(getattr(parent, "Impl", None), part, None)
            elif (kind == "action" and part in _ACTION_PARTS) or (kind == "srv" and part in _SERVICE_PARTS):
                cls = getattr(parent, part, None)
    if cls is None:
        raise UnknownMessageType(f"{type_name}: {package}.{kind} has no such message class")
    return cls
