"""Ground commands (Table 1) into the CRS: an in-process queue with acknowledgements, and their execution.

Interface for the ground link (or any other front end)::

    queue.submit("set_blackboard_value", {"key": "clear_fault", "value": True}, on_ack)

A command is validated twice, with the same rules (:meth:`CommandProcessor.check`): when it
arrives, and again when the tree's Process Ground Command step (one per tick) executes it, since
the CRS's state may have changed while it waited. Its acknowledgements go to ``on_ack(stage,
reason)``: ``REJECTED`` (with the reason) when refused on arrival, or ``ACCEPTED`` exactly once
and then one of ``COMPLETED`` or ``FAILED`` (reason), the latter also when the execution check
refuses it. A rejected or failed command changes nothing.

``submit`` does the arrival check and the acceptance itself. A front end that acknowledges on its
own (the CCSDS ground link, which refuses a bad packet and a command the CRS refuses with one
``rejected`` ack) calls ``queue.check(name, params)`` on arrival, acknowledges, and hands the
accepted command over with ``queue.put_accepted(name, params, on_outcome)``, whose callback hears
only ``COMPLETED`` or ``FAILED``.

Commands and their parameters (the names of ``config/ccsds/definitions.yaml``):

=====================  =====================================  ======================================
command                params                                 accepted when
=====================  =====================================  ======================================
start                  -                                      not started, not paused, not stopped
pause                  -                                      started and not paused
resume                 -                                      paused
stop                   -                                      not already stopping
set_blackboard_value   key, value (bool/int/float/str)        the key's whitelist or the tower
                                                              model's rules accept it (below)
set_actuator_state     actuator, state, value (optional)      the actuator table has the state, and
                                                              not building: idle, fault or done
=====================  =====================================  ======================================

Set Blackboard Value reaches what its key names (:mod:`tlt_common.bt.ground_keys`): a key of the
CRS's whitelist; ``ars_x/<key>`` or ``ars_y/<key>``, checked here against the ARSs' whitelist
(``ars_writable_blackboard`` of the CRS configuration) and forwarded to that ARS's
``set_blackboard_value`` service, whose answer completes or fails the command; ``tower/<member>``
(a mark of ``MEMBER_MARKS``) and ``dispenser/<name>`` (a count), corrections of the tower model
under its rules, refused while building as actuator commands are, and reported as events.

Set Actuator State takes exactly the actuators and states of the definitions file's
``actuators`` table, the one the GSW offers; the processor refuses to start on a table that names
a state it cannot drive (:func:`check_actuator_table`).

Start, Pause, Resume and Stop are forwarded to each ARS with the ``GroundCommand`` service; a
forward that gets no answer within ``timeouts.forward_s`` is reported in the completion detail and
as a warning event, but does not undo the CRS's own change. Actuator commands and writes to an ARS
run asynchronously (service call or trajectory goal) and complete when the driver or the ARS
answers.
"""

from __future__ import annotations

import collections
import itertools
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from py_trees.common import Status

from tlt_common import ros_names
from tlt_common.bt.ground_keys import DISPENSER, MEMBER_MARKS, TOWER, route
from tlt_common.bt.nodes import Action
from tlt_common.bt.ros import shared_action_client, shared_service_client
from tlt_common.bt.writable_blackboard import WritableBlackboard, value_msg
from tlt_common.ccsds.definitions import ActuatorDef, Definitions, load_definitions
from tlt_common.ccsds.reasons import AckStage
from tlt_common.config_schema import ConfigError
from tlt_common.mission.tower_model import STATE_NAMES, TransitionRefused
from tlt_crs.behaviours.actuators import trajectory_goal, trajectory_ok
from tlt_crs.context import CrsContext, RunState

AckCallback = Callable[[AckStage, str], None]
COMMANDS = ("start", "stop", "pause", "resume", "set_blackboard_value", "set_actuator_state")
FORWARD_CODES = {"start": 0, "stop": 1, "pause": 2, "resume": 3}  # GroundCommand.Request constants
LIFTER_MODES = {"hardware_control": 1, "crs_control": 2, "safe": 3}
# What the CRS can drive (its _do_set_actuator_state): actuator -> (states, the states that take a
# value). The definitions file's table, which the GSW offers, must stay within it.
DRIVEN = {
    ros_names.LIFTER: (tuple(LIFTER_MODES), ()),
    ros_names.TOP_GRIPPERS: (("engage", "disengage"), ()),
    ros_names.ACTIVE_GRIPPERS: (("engage", "disengage"), ()),
    ros_names.CAMERA_MOUNTS: (("stow", "inspect_part", "inspect_bay", "move"), ("move",)),
}


def check_actuator_table(defs: Definitions) -> None:
    """Raise ``ConfigError`` (file, key, reason) if the definitions' ``actuators`` table offers an
    actuator or state the CRS cannot drive, or a value where the CRS takes none (or none where it
    needs one): the GSW offers that table, so the two must agree."""
    for name, actuator in defs.actuators.items():
        if name not in DRIVEN:
            raise ConfigError(
                defs.source,
                f"actuators.{name}",
                f"the CRS drives no actuator {name!r} (it drives {', '.join(DRIVEN)})",
            )
        states, value_states = DRIVEN[name]
        for state in actuator.states:
            if state not in states:
                raise ConfigError(
                    defs.source,
                    f"actuators.{name}.states",
                    f"the CRS cannot drive {name} to {state!r} (its states: {', '.join(states)})",
                )
        if set(actuator.value_states) != set(value_states) & set(actuator.states):
            needs = ", ".join(s for s in value_states if s in actuator.states) or "none"
            raise ConfigError(
                defs.source, f"actuators.{name}.value", f"the states of {name} that take a value are: {needs}"
            )


@dataclass
class Command:
    name: str
    params: Mapping[str, Any]
    on_ack: AckCallback | None = None
    id: int = 0

    def ack(self, stage: AckStage, reason: str = "") -> None:
        if self.on_ack is not None:
            self.on_ack(stage, reason)


class CommandQueue:
    """Thread-safe queue of accepted commands, with the arrival check (``check``: why a command
    would be refused now, None if it would not)."""

    def __init__(self, check: Callable[[str, Mapping[str, Any]], str | None]) -> None:
        self._check = check
        self._lock = threading.Lock()
        self._items: collections.deque[Command] = collections.deque()
        self._ids = itertools.count(1)

    def check(self, name: str, params: Mapping[str, Any] | None = None) -> str | None:
        """Why ``name`` with ``params`` would be refused on arrival now; None if it would be accepted."""
        try:
            return self._check(name, dict(params or {}))
        except Exception as exc:  # a checker bug must be a refusal, not a crash of the caller
            return f"command could not be checked: {exc}"

    def submit(
        self, name: str, params: Mapping[str, Any] | None = None, on_ack: AckCallback | None = None
    ) -> Command:
        """Check the command, then acknowledge it REJECTED, or ACCEPTED and queue it."""
        command = Command(name, dict(params or {}), on_ack, next(self._ids))
        refusal = self.check(name, command.params)
        if refusal:
            command.ack(AckStage.REJECTED, refusal)
            return command
        # Acknowledged before it is queued: the tree's outcome can never overtake the acceptance.
        command.ack(AckStage.ACCEPTED, "")
        self._append(command)
        return command

    def put_accepted(
        self, name: str, params: Mapping[str, Any] | None = None, on_outcome: AckCallback | None = None
    ) -> Command:
        """Queue a command its front end has already checked and acknowledged as accepted;
        ``on_outcome`` hears only COMPLETED or FAILED."""
        command = Command(name, dict(params or {}), on_outcome, next(self._ids))
        self._append(command)
        return command

    def _append(self, command: Command) -> None:
        with self._lock:
            self._items.append(command)

    def pop(self) -> Command | None:
        if not self._items:  # the tick's common case; a command appended meanwhile waits a tick
            return None
        with self._lock:
            return self._items.popleft() if self._items else None

    def __len__(self) -> int:
        with self._lock:
            return len(self._items)


# ----- asynchronous steps of a command ----------------------------------------------------------
class _ServiceStep:
    """A service call of a command; ``poll`` returns None while running, else (ok, text)."""

    def __init__(self, label: str, client: Any, request: Any, ok: Callable[[Any], tuple[bool, str]]) -> None:
        self.label, self.client, self.request, self.ok = label, client, request, ok
        self.future: Any = None

    def poll(self) -> tuple[bool, str] | None:
        if self.future is None:
            if not self.client.service_is_ready():
                return None
            self.future = self.client.call_async(self.request)
        if not self.future.done():
            return None
        return self.ok(self.future.result())

    def give_up(self) -> str:
        if self.future is not None:
            self.client.remove_pending_request(self.future)
        return "not available" if self.future is None else "no answer"


class _GoalStep:
    """A trajectory goal of a command; ``poll`` returns None while running, else (ok, text)."""

    def __init__(self, label: str, client: Any, goal: Any) -> None:
        self.label, self.client, self.goal = label, client, goal
        self.send: Any = None
        self.result: Any = None

    def poll(self) -> tuple[bool, str] | None:
        if self.send is None:
            if not self.client.server_is_ready():
                return None
            self.send = self.client.send_goal_async(self.goal)
        if self.result is None:
            if not self.send.done():
                return None
            handle = self.send.result()
            if handle is None or not handle.accepted:
                return False, "goal rejected"
            self.result = handle.get_result_async()
        if not self.result.done():
            return None
        return trajectory_ok(self.result.result().result)

    def give_up(self) -> str:
        if self.send is not None and self.send.done() and self.send.result() is not None:
            self.send.result().cancel_goal_async()
        return "not available" if self.send is None else "no result"


@dataclass
class _Operation:
    command: Command
    steps: list[Any]
    deadline: float
    fatal: bool  # a step that fails makes the command FAILED (else only reported)
    then: Callable[[bool, str], None] | None = None
    outcomes: dict[int, tuple[bool, str]] = field(default_factory=dict)


class CommandProcessor:
    """Checks and executes commands against one CRS context, with what the CRS node does for them:

    * ``hold``: on Pause (and a hold the CRS decides), pre-empt the running actuator motions;
    * ``stop_tree``: on Stop, interrupt the tree (the processor then puts the lifter in Safe and
      forwards STOP);
    * ``on_stopped``: once Stop has run its course, end the node.
    """

    def __init__(
        self,
        ctx: CrsContext,
        *,
        hold: Callable[[], None],
        stop_tree: Callable[[], None],
        on_stopped: Callable[[], None],
        definitions: Definitions | None = None,
    ) -> None:
        """Raises ``ConfigError`` for an actuator table the CRS cannot drive or an ARS whitelist
        that does not load."""
        self.ctx = ctx
        defs = definitions or load_definitions()
        check_actuator_table(defs)
        self.actuators: Mapping[str, ActuatorDef] = defs.actuators
        ars_registry = WritableBlackboard.load(ctx.config.ars_writable_blackboard)
        self.ars_registries = dict.fromkeys(ros_names.ARS_AGENTS, ars_registry)
        self.queue = CommandQueue(self.check)
        self._hold = hold
        self._stop_tree = stop_tree
        self._on_stopped = on_stopped
        self._operations: list[_Operation] = []
        self.last = ""

    # ----- checks (no state change) -----
    def check(self, name: str, params: Mapping[str, Any]) -> str | None:
        """Why the command would be refused in the CRS's state now (None: it would not); the rules
        of the table above, applied on arrival and again on execution."""
        ctx = self.ctx
        if name not in COMMANDS:
            return f"unknown command '{name}' (known: {', '.join(COMMANDS)})"
        if ctx.stopped:
            return "the CRS is stopping"
        if name == "start":
            if ctx.paused:
                return "the CRS is paused; send resume"
            if ctx.started:
                return "already started"
            not_ready = ctx.not_ready()
            if not_ready:
                return f"not ready: {not_ready}"
        elif name == "pause":
            if not ctx.started:
                return "not started; nothing to pause"
            if ctx.paused:
                return "already paused"
        elif name == "resume":
            if not ctx.paused:
                return "not paused"
        elif name == "set_blackboard_value":
            if "key" not in params or "value" not in params:
                return "set_blackboard_value needs 'key' and 'value'"
            return self._check_write(str(params["key"]), params["value"])
        elif name == "set_actuator_state":
            return self._check_actuator(params)
        return None

    def _check_write(self, key: str, value: Any) -> str | None:
        ctx, target = self.ctx, route(key)
        if target.target == TOWER:
            if not isinstance(value, str):
                return f"key '{key}': a member's mark is a string ({', '.join(MEMBER_MARKS)}), not {value!r}"
            with ctx.model.lock:
                return ctx.model.check_correction(target.name, value) or self._building(
                    "the tree keeps the tower model"
                )
        if target.target == DISPENSER:
            with ctx.model.lock:
                return ctx.model.check_remaining(target.name, value) or self._building(
                    "the tree keeps the tower model"
                )
        if target.target in self.ars_registries:
            refused = self.ars_registries[target.target].check(target.name, value).reason
            return f"{target.target}: {refused}" if refused else None
        result = ctx.registry.check(target.name, value)
        if not result.accepted:
            return result.reason
        if target.name == "clear_fault" and value is True and not ctx.fault:
            # Taken now, it would stand until the next fault and clear that one unseen.
            if ctx.link_fault:
                return "the lifter link fault clears itself when the link is back"
            return "no fault to clear"
        return None

    def _building(self, why: str) -> str | None:
        """Why the ground may not change what the tree changes itself (actuators, the tower
        model) now; ``why`` says what the tree does with it."""
        run_state = self.ctx.run_state
        if run_state in (RunState.RUNNING, RunState.PAUSED):
            return (
                f"refused while building (run state {run_state.name.lower()}): {why};"
                " wait for a fault, the end of the build, or stop"
            )
        if self.ctx.link_fault:
            # The build is only held: it goes on by itself when the link is back, and a change
            # made meanwhile would be where the tree does not expect it.
            return (
                "refused while building (run state fault: the build is held until the lifter link"
                f" is back and then goes on): {why}; stop first"
            )
        return None

    def _check_actuator(self, params: Mapping[str, Any]) -> str | None:
        actuator, state, value = params.get("actuator"), params.get("state"), params.get("value")
        table = self.actuators.get(actuator) if isinstance(actuator, str) else None
        if table is None:
            known = ", ".join(self.actuators)
            return f"actuator '{actuator}' is not driven by the CRS (CRS actuators: {known})"
        if state not in table.states:
            return f"actuator '{actuator}' has no state '{state}' (states: {', '.join(table.states)})"
        if state in table.value_states:
            # The table's value states always carry a range (definitions.py checks it on load).
            low, high = table.value_minimum or 0.0, table.value_maximum or 0.0
            if not isinstance(value, int | float) or isinstance(value, bool):
                return (
                    f"'{actuator}' state '{state}' needs a numeric value ({low:g} .. {high:g} {table.unit})"
                )
            if not low <= value <= high:
                return f"'{actuator}' value {value!r} is outside {low:g} .. {high:g} {table.unit}"
        elif value is not None:
            return f"'{actuator}' state '{state}' takes no value"
        return self._building("actuators are driven by the tree")

    # ----- holds the CRS itself decides -----
    def hold_build(self, reason: str) -> None:
        """Hold the build as Pause does (mission clock, the CRS's running motions, PAUSE to each
        ARS), for ``reason`` rather than the operator; :meth:`release_build` ends it."""
        self.ctx.clock.pause(reason)
        self._hold()
        self._forward(Command("pause", {}))

    def release_build(self, reason: str) -> None:
        """End the hold for ``reason``; the ARSs resume unless the operator has paused meanwhile."""
        self.ctx.clock.resume(reason)
        if not self.ctx.clock.held:
            self._forward(Command("resume", {}))

    # ----- execution -----
    def process_next(self) -> bool:
        """Execute one queued command, if any; return whether there was one."""
        command = self.queue.pop()
        if command is None:
            return False
        # The execution check: the state may have changed since the command was accepted.
        refusal = self.check(command.name, command.params)
        self.last = command.name
        if refusal:
            command.ack(AckStage.FAILED, refusal)
            return True
        try:
            getattr(self, f"_do_{command.name}")(command)
        except Exception as exc:  # a command must fail with its reason, never take the CRS down
            self.ctx.event(3, "COMMAND_FAILED", f"{command.name} failed: {exc}")
            command.ack(AckStage.FAILED, f"{command.name} failed: {exc}")
        return True

    def _forward(self, command: Command, then: Callable[[bool, str], None] | None = None) -> None:
        from tlt_interfaces.srv import GroundCommand

        steps = []
        for ars in ros_names.ARS_AGENTS:
            client = shared_service_client(
                self.ctx.node, GroundCommand, ros_names.ground_command_service(ars)
            )
            request = GroundCommand.Request(command=FORWARD_CODES[command.name])
            steps.append(_ServiceStep(ars, client, request, lambda r: (bool(r.accepted), r.reason)))
        self._operations.append(
            _Operation(
                command, steps, self.ctx.ros_seconds() + self.ctx.config.timeouts.forward_s, False, then
            )
        )

    def _do_start(self, command: Command) -> None:
        self.ctx.board.set("started", True)
        self.ctx.event(1, "STARTED", "start command: building")
        self._forward(command)

    def _do_pause(self, command: Command) -> None:
        self.ctx.clock.pause()
        self._hold()
        self.ctx.event(1, "PAUSED", "pause command: tree halted, actuators holding")
        self._forward(command)

    def _do_resume(self, command: Command) -> None:
        self.ctx.clock.resume()
        self.ctx.event(1, "RESUMED", "resume command: continuing where paused")
        self._forward(command)

    def _do_stop(self, command: Command) -> None:
        from tlt_interfaces.srv import GroundCommand, SetLifterMode

        ctx = self.ctx
        ctx.stopped = True
        ctx.board.set("started", False)
        self._stop_tree()
        ctx.event(2, "STOPPING", "stop command: canceling work, lifter to Safe, shutting down")
        steps: list[Any] = [
            _ServiceStep(
                "lifter safe",
                shared_service_client(ctx.node, SetLifterMode, ros_names.LIFTER_SET_MODE),
                SetLifterMode.Request(mode=LIFTER_MODES["safe"]),
                lambda r: (bool(r.success), r.reason),
            )
        ]
        for ars in ros_names.ARS_AGENTS:
            client = shared_service_client(ctx.node, GroundCommand, ros_names.ground_command_service(ars))
            steps.append(
                _ServiceStep(
                    ars, client, GroundCommand.Request(command=1), lambda r: (bool(r.accepted), r.reason)
                )
            )
        limit = max(ctx.config.timeouts.forward_s, ctx.config.timeouts.service_s)
        self._operations.append(
            _Operation(command, steps, ctx.ros_seconds() + limit, False, lambda ok, why: self._on_stopped())
        )

    def _do_set_blackboard_value(self, command: Command) -> None:
        ctx = self.ctx
        key, value = str(command.params["key"]), command.params["value"]
        target = route(key)
        if target.target in (TOWER, DISPENSER):
            try:
                if target.target == TOWER:
                    ctx.model.correct_member(target.name, value)
                    state = STATE_NAMES[ctx.model.state(target.name)]
                    ctx.event(
                        1, "TOWER_CORRECTED", f"{target.name} marked {value} from the ground: now {state}"
                    )
                else:
                    ctx.model.set_remaining(target.name, value)
                    ctx.event(
                        1, "DISPENSER_CORRECTED", f"{target.name} holds {value} part(s), as the ground says"
                    )
            except TransitionRefused as refused:
                command.ack(AckStage.FAILED, refused.reason)
                return
            command.ack(AckStage.COMPLETED, "")
            return
        if target.target in self.ars_registries:
            self._forward_write(command, target.target, target.name, value)
            return
        with ctx.lock:
            result = ctx.registry.write(target.name, value)
        if result.accepted:
            ctx.event(1, "BLACKBOARD_SET", f"{key} = {value!r}")
            command.ack(AckStage.COMPLETED, "")
        else:
            command.ack(AckStage.FAILED, result.reason)

    def _forward_write(self, command: Command, ars: str, name: str, value: Any) -> None:
        """A write to an ARS key: its SetBlackboardValue service applies it, or says why not."""
        from tlt_interfaces.srv import SetBlackboardValue

        ctx = self.ctx
        spec = self.ars_registries[ars].keys[name]
        client = shared_service_client(ctx.node, SetBlackboardValue, ros_names.set_blackboard_service(ars))
        request = SetBlackboardValue.Request(key=name, value=value_msg(value, spec.type))
        step = _ServiceStep(ars, client, request, lambda r: (bool(r.accepted), r.reason))

        def then(ok: bool, detail: str) -> None:
            if ok:
                ctx.event(1, "BLACKBOARD_SET", f"{ars}/{name} = {value!r}")

        limit = max(ctx.config.timeouts.forward_s, ctx.config.timeouts.service_s)
        self._operations.append(_Operation(command, [step], ctx.ros_seconds() + limit, True, then))

    def _do_set_actuator_state(self, command: Command) -> None:
        from tlt_interfaces.action import FollowJointTrajectory
        from tlt_interfaces.srv import SetLifterMode

        ctx, params = self.ctx, command.params
        actuator, state = params["actuator"], params["state"]
        config = ctx.config
        if actuator == ros_names.LIFTER:
            client = shared_service_client(ctx.node, SetLifterMode, ros_names.LIFTER_SET_MODE)
            step: Any = _ServiceStep(
                "lifter",
                client,
                SetLifterMode.Request(mode=LIFTER_MODES[state]),
                lambda r: (bool(r.success), r.reason),
            )
        elif actuator == ros_names.TOP_GRIPPERS:
            from std_msgs.msg import Float64MultiArray

            setup = config.top_grippers
            stroke = setup.engage if state == "engage" else setup.disengage
            publisher = ctx.node.create_publisher(
                Float64MultiArray, ros_names.position_command_topic(ros_names.TOP_GRIPPERS), 10
            )
            publisher.publish(Float64MultiArray(data=[stroke] * len(setup.joints)))
            ctx.event(1, "ACTUATOR_SET", f"{actuator} -> {state}")
            command.ack(AckStage.COMPLETED, "commanded")
            return
        else:
            if actuator == ros_names.ACTIVE_GRIPPERS:
                setup = config.active_grippers
                joints, seconds = setup.joints, setup.move_time_s
                positions = [setup.engage if state == "engage" else setup.disengage] * len(joints)
            else:
                cam = config.camera_mounts
                joints, seconds = cam.joints, cam.move_time_s
                if state == "move":
                    positions = [float(params["value"])] * len(joints)
                else:
                    positions = list(cam.inward if state in ("inward", "inspect_bay") else cam.outward)
            client = shared_action_client(
                ctx.node, FollowJointTrajectory, ros_names.trajectory_action(actuator)
            )
            step = _GoalStep(actuator, client, trajectory_goal(joints, positions, seconds))
        ctx.event(1, "ACTUATOR_SET", f"{actuator} -> {state}")
        limit = config.timeouts.actuator_s
        self._operations.append(_Operation(command, [step], ctx.ros_seconds() + limit, True))

    # ----- progress of asynchronous commands -----
    def poll(self) -> None:
        """Advance running commands; acknowledge those that finished or ran out of time."""
        now = self.ctx.ros_seconds()
        for op in list(self._operations):
            for i, step in enumerate(op.steps):
                if i not in op.outcomes:
                    try:
                        outcome = step.poll()
                    except Exception as exc:
                        outcome = (False, str(exc))
                    if outcome is not None:
                        op.outcomes[i] = outcome
            timed_out = now > op.deadline
            if len(op.outcomes) < len(op.steps) and not timed_out:
                continue
            problems = []
            for i, step in enumerate(op.steps):
                if i not in op.outcomes:
                    problems.append(f"{step.label}: {step.give_up()} within the time limit")
                elif not op.outcomes[i][0]:
                    problems.append(f"{step.label}: {op.outcomes[i][1] or 'refused'}")
            self._operations.remove(op)
            detail = "; ".join(problems)
            ok = not (op.fatal and problems)
            if problems:
                self.ctx.event(2, "COMMAND_INCOMPLETE", f"{op.command.name}: {detail}")
            op.command.ack(AckStage.COMPLETED if ok else AckStage.FAILED, detail)
            if op.then is not None:
                op.then(ok, detail)

    @property
    def busy(self) -> bool:
        return bool(self._operations)


class ProcessGroundCommand(Action):
    """Execute the next pending ground command, if any (Fig. 13).

    Reads/writes: whatever the command does (blackboard keys, ``started``). SUCCESS always: a
    command's outcome is reported by its acknowledgement, not by the tree.
    """

    def __init__(self, processor: CommandProcessor) -> None:
        super().__init__("Process Ground Command")
        self.processor = processor

    def update(self) -> Status:
        if self.processor.process_next():
            self.feedback_message = f"processed '{self.processor.last}'"
        else:
            self.feedback_message = "no command pending"
        return Status.SUCCESS


__all__ = [
    "COMMANDS",
    "DRIVEN",
    "Command",
    "CommandProcessor",
    "CommandQueue",
    "ProcessGroundCommand",
    "check_actuator_table",
]
