"""Action and Condition node types (Colledanchise and Ögren; paper §V.C, Table 3) on py_trees.

=========  ==================  =========================  ================
Node type  Succeeds            Fails                      Running
=========  ==================  =========================  ================
Action     upon completion     if impossible to complete  during completion
Condition  if true             if false                   never
=========  ==================  =========================  ================

Sequences ("-->") and Fallbacks ("?") are py_trees' own ``Sequence`` and ``Selector``.

Contract enforcement
--------------------
A :class:`Condition` implements :meth:`Condition.evaluate` and may not override ``update``
(defining ``update`` in a subclass raises ``TypeError`` at class creation). If ``evaluate`` answers
RUNNING or INVALID, or raises, the condition answers FAILURE and logs an error naming the
condition: a robot must not act on a condition it could not evaluate. With ``strict=True`` (or
:data:`Condition.strict_default` set to True, as the tests do) it raises
:class:`ContractViolation` instead, so a wrong condition is caught at the first tick in testing.

An :class:`Action` implements ``update`` as in py_trees. An answer of INVALID (not a result a
leaf may give) is turned into FAILURE with a logged error, or raises in strict mode.

Docstring convention for every behaviour of the project: say what it reads and writes on the
blackboard, and when it answers SUCCESS, FAILURE and RUNNING.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any, ClassVar

import py_trees
from py_trees.common import Status

_log = logging.getLogger("tlt_common.bt")
_STATUSES = tuple(Status)


class ContractViolation(RuntimeError):
    """A node answered a status its node type may not give (strict mode only)."""


class Action(py_trees.behaviour.Behaviour):
    """Base of every action leaf: RUNNING while working, SUCCESS when done, FAILURE if it cannot complete.

    Subclasses implement ``update()`` (and ``initialise``/``terminate`` as needed). They set
    ``feedback_message`` to say what they are doing, and to the reason when they fail;
    :meth:`fail` does both in one call.
    """

    kind: ClassVar[str] = "action"
    strict_default: ClassVar[bool] = False

    def __init__(self, name: str, *, strict: bool | None = None) -> None:
        super().__init__(name)
        self.strict = self.strict_default if strict is None else strict

    def tick(self):
        # py_trees' Behaviour.tick (2.6) step for step, with the status check added. Written out
        # rather than wrapping super().tick(): a wrapping generator cost every action a second
        # generator frame per tick, a tenth of a bare leaf's tick.
        self.logger.debug(f"{self.__class__.__name__}.tick()")
        if self.status != Status.RUNNING:
            self.initialise()
        new_status = self.update()
        if new_status not in _STATUSES:
            self.logger.error(
                f"A behaviour returned an invalid status, setting to INVALID [{new_status}][{self.name}]"
            )
            new_status = Status.INVALID
        if new_status != Status.RUNNING:
            self.stop(new_status)
        self.status = new_status
        if new_status is Status.INVALID:
            self._violation("answered INVALID; an action answers RUNNING, SUCCESS or FAILURE")
        yield self

    def _violation(self, what: str) -> None:
        text = f"action '{self.name}' ({type(self).__name__}) {what}"
        if self.strict:
            raise ContractViolation(text)
        _log.error("%s: treated as FAILURE", text)
        self.feedback_message = f"contract violation: {what}"
        self.stop(Status.FAILURE)

    def fail(self, reason: str) -> Status:
        """Record ``reason`` as the feedback message and return FAILURE."""
        self.feedback_message = reason
        return Status.FAILURE


class Condition(py_trees.behaviour.Behaviour):
    """Base of every condition leaf: SUCCESS if true, FAILURE if false, never RUNNING.

    Subclasses implement :meth:`evaluate`, returning a bool (a numpy bool too) or a Status of
    SUCCESS/FAILURE.
    """

    kind: ClassVar[str] = "condition"
    strict_default: ClassVar[bool] = False

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "update" in cls.__dict__:
            raise TypeError(
                f"{cls.__name__}: a Condition implements evaluate(), not update(),"
                " so it cannot answer RUNNING"
            )

    def __init__(self, name: str, *, strict: bool | None = None) -> None:
        super().__init__(name)
        self.strict = self.strict_default if strict is None else strict

    def evaluate(self) -> bool | Status:
        """Return whether the condition holds. Must not block."""
        raise TypeError(f"{type(self).__name__} must implement evaluate()")

    def update(self) -> Status:
        try:
            answer = self.evaluate()
        except ContractViolation:
            raise
        except Exception as exc:
            if self.strict:
                raise
            _log.error("condition '%s' raised %r: treated as FAILURE", self.name, exc)
            self.feedback_message = f"evaluation error: {exc}"
            return Status.FAILURE
        if answer is True or answer is Status.SUCCESS:
            return Status.SUCCESS
        if answer is False or answer is Status.FAILURE:
            return Status.FAILURE
        if type(answer).__module__ == "numpy" and type(answer).__name__ in ("bool", "bool_"):
            # Sensor conditions often end in numpy reductions such as np.all(engaged).
            return Status.SUCCESS if answer else Status.FAILURE
        what = f"condition '{self.name}' ({type(self).__name__}) answered {answer!r}; only true/false allowed"
        if self.strict:
            raise ContractViolation(what)
        _log.error("%s: treated as FAILURE", what)
        self.feedback_message = f"contract violation: answered {answer!r}"
        return Status.FAILURE


class BlackboardCondition(Condition):
    """True when ``predicate(value)`` holds for blackboard key ``key``.

    Reads: ``key``. Writes: nothing.
    SUCCESS when the key exists and the predicate is true; FAILURE when it is false or the key is
    not set (feedback says which).
    """

    def __init__(
        self,
        name: str,
        key: str,
        predicate: Callable[[Any], bool] = bool,
        *,
        strict: bool | None = None,
    ) -> None:
        super().__init__(name, strict=strict)
        self.key = key
        self.predicate = predicate
        self._bb = self.attach_blackboard_client(name=name)
        self._bb.register_key(key=key, access=py_trees.common.Access.READ)

    def evaluate(self) -> bool:
        try:
            value = self._bb.get(self.key)
        except KeyError:
            self.feedback_message = f"'{self.key}' is not set"
            return False
        result = bool(self.predicate(value))
        self.feedback_message = f"{self.key}={value!r}"
        return result


class SetBlackboard(Action):
    """Write ``value`` (or ``value_fn()``) to blackboard key ``key``.

    Reads: nothing. Writes: ``key``. SUCCESS at once; never RUNNING; FAILURE if ``value_fn`` raises.
    """

    def __init__(
        self,
        name: str,
        key: str,
        value: Any = None,
        *,
        value_fn: Callable[[], Any] | None = None,
        strict: bool | None = None,
    ) -> None:
        super().__init__(name, strict=strict)
        self.key = key
        self.value = value
        self.value_fn = value_fn
        self._bb = self.attach_blackboard_client(name=name)
        self._bb.register_key(key=key, access=py_trees.common.Access.WRITE)

    def update(self) -> Status:
        try:
            value = self.value_fn() if self.value_fn is not None else self.value
        except Exception as exc:
            return self.fail(f"cannot compute '{self.key}': {exc}")
        self._bb.set(self.key, value)
        self.feedback_message = f"{self.key}={value!r}"
        return Status.SUCCESS


def node_kind(behaviour: py_trees.behaviour.Behaviour) -> str:
    """The Table 3 node type: fallback, sequence, parallel, condition, action or decorator."""
    if isinstance(behaviour, py_trees.composites.Selector):
        return "fallback"
    if isinstance(behaviour, py_trees.composites.Sequence):
        return "sequence"
    if isinstance(behaviour, py_trees.composites.Parallel):
        return "parallel"
    if isinstance(behaviour, py_trees.decorators.Decorator):
        return "decorator"
    if isinstance(behaviour, Condition):
        return "condition"
    return "action"


__all__ = [
    "Action",
    "BlackboardCondition",
    "Condition",
    "ContractViolation",
    "SetBlackboard",
    "node_kind",
]
