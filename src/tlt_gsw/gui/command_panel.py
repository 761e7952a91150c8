"""Command panel for the six commands of Table 1, with confirmation of the hazardous ones.

Start, Stop, Pause and Resume are one button each; Set Blackboard Value takes a key (completed
from every agent's whitelist, which also picks the value's type and shows the key's range and
meaning) and a typed value; Correct Tower Model marks a member (placed, unplaced, discarded,
needs_inspection) or sets the parts a dispenser holds, as Set Blackboard Value of the keys of
:mod:`tlt_common.bt.ground_keys`; Set Actuator State takes an actuator, one of its states and, for
the states that take one, a value, offering exactly the definitions file's table, which is what
the CRS accepts. A command marked ``hazardous`` there (Stop, Set Actuator State) is sent only
after the operator confirms a dialog. Sending goes through
``sender(name, params) -> Future`` (the link thread's :meth:`LinkWorker.submit`); without a sender
(replay, monitor-only) the panel is disabled and says why. A command that cannot be sent (bad
parameter, link down) is reported in the panel's status line; acknowledgements appear in the
command history, which reads the archive.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from concurrent.futures import Future
from typing import Any

from PySide6 import QtCore, QtWidgets

from tlt_common.bt.ground_keys import MEMBER_MARKS, dispenser_key, load_whitelists, member_key, writable_keys
from tlt_common.bt.writable_blackboard import KeySpec
from tlt_common.ccsds.definitions import CommandDef, Definitions
from tlt_common.mission.schema import Mission
from tlt_gsw.gui.style import BAD_COLOUR, HAZARDOUS_BUTTON

Sender = Callable[[str, Mapping[str, Any]], Future]
SIMPLE_COMMANDS = ("start", "pause", "resume", "stop")
VALUE_TYPES = ("float", "int", "bool", "str")


class ParameterError(ValueError):
    """A parameter typed in the panel that cannot be converted (the message says which and why)."""


def parse_typed_value(kind: str, text: str) -> Any:
    """A Set Blackboard Value value typed as ``kind`` (float, int, bool or str)."""
    text = text.strip() if kind != "str" else text
    try:
        if kind == "float":
            return float(text)
        if kind == "int":
            return int(text, 0)
        if kind == "bool":
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError(f"{text!r} is not true or false")
            return text.lower() in ("true", "1")
    except ValueError as exc:
        raise ParameterError(f"value: {exc}") from None
    if kind == "str":
        return text
    raise ParameterError(f"unknown value type {kind!r}")


class CommandPanel(QtWidgets.QGroupBox):
    """Buttons and forms for the commands; see the module docstring."""

    def __init__(
        self,
        defs: Definitions,
        sender: Sender | None,
        disabled_reason: str = "",
        parent: QtWidgets.QWidget | None = None,
        *,
        mission: Mission | None = None,
        keys: Mapping[str, KeySpec] | None = None,
    ) -> None:
        """``keys``: the writable keys offered (default: every agent's project whitelist);
        ``mission``: its members and dispensers are offered for corrections."""
        super().__init__("Commands", parent)
        self.defs = defs
        self.keys = dict(keys) if keys is not None else writable_keys(load_whitelists())
        # Not ``self.sender``: that would hide QObject.sender().
        self._sender = sender
        self.pending: list[tuple[str, Future]] = []
        self.confirm: Callable[[CommandDef, Mapping[str, Any]], bool] = self._ask
        self.buttons: dict[str, QtWidgets.QPushButton] = {}
        layout = QtWidgets.QVBoxLayout(self)

        row = QtWidgets.QHBoxLayout()
        for name in SIMPLE_COMMANDS:
            cmd = defs.command(name)
            button = QtWidgets.QPushButton(name.capitalize())
            button.setObjectName(f"command_{name}")
            button.setToolTip(
                cmd.description + (" (hazardous: asks for confirmation)" if cmd.hazardous else "")
            )
            if cmd.hazardous:
                button.setStyleSheet(HAZARDOUS_BUTTON)
            button.clicked.connect(lambda _=False, n=name: self.send(n, {}))
            row.addWidget(button)
            self.buttons[name] = button
        layout.addLayout(row)

        bb = QtWidgets.QGroupBox("Set Blackboard Value")
        form = QtWidgets.QGridLayout(bb)
        self.bb_key = QtWidgets.QLineEdit()
        self.bb_key.setPlaceholderText("key, e.g. lifter_speed or ars_x/settle_s")
        self.bb_key.setCompleter(_completer(list(self.keys), self.bb_key))
        self.bb_key.textChanged.connect(self._key_changed)
        self.bb_type = QtWidgets.QComboBox()
        self.bb_type.addItems(VALUE_TYPES)
        self.bb_value = QtWidgets.QLineEdit()
        self.bb_value.setPlaceholderText("value")
        send_bb = QtWidgets.QPushButton("Send")
        send_bb.setObjectName("command_set_blackboard_value")
        send_bb.clicked.connect(self._send_blackboard)
        form.addWidget(QtWidgets.QLabel("Key"), 0, 0)
        form.addWidget(self.bb_key, 0, 1, 1, 3)
        form.addWidget(QtWidgets.QLabel("Value"), 1, 0)
        form.addWidget(self.bb_type, 1, 1)
        form.addWidget(self.bb_value, 1, 2)
        form.addWidget(send_bb, 1, 3)
        self.buttons["set_blackboard_value"] = send_bb
        layout.addWidget(bb)

        tower = QtWidgets.QGroupBox("Correct Tower Model")
        tgrid = QtWidgets.QGridLayout(tower)
        self.member = QtWidgets.QLineEdit()
        self.member.setPlaceholderText("member id, e.g. bay1/vertical/x0_y1")
        self.mark = QtWidgets.QComboBox()
        self.mark.addItems(MEMBER_MARKS)
        self.dispenser = QtWidgets.QLineEdit()
        self.dispenser.setPlaceholderText("dispenser, e.g. vertical_dispenser_x")
        self.count = QtWidgets.QSpinBox()
        self.count.setRange(0, 999)
        if mission is not None:
            self.member.setCompleter(_completer([m.id for m in mission.members], self.member))
            self.dispenser.setCompleter(_completer(list(mission.dispensers), self.dispenser))
        send_member = QtWidgets.QPushButton("Send")
        send_member.setObjectName("command_correct_member")
        send_member.clicked.connect(self._send_member)
        send_dispenser = QtWidgets.QPushButton("Send")
        send_dispenser.setObjectName("command_correct_dispenser")
        send_dispenser.clicked.connect(self._send_dispenser)
        tgrid.addWidget(QtWidgets.QLabel("Member"), 0, 0)
        tgrid.addWidget(self.member, 0, 1)
        tgrid.addWidget(self.mark, 0, 2)
        tgrid.addWidget(send_member, 0, 3)
        tgrid.addWidget(QtWidgets.QLabel("Dispenser"), 1, 0)
        tgrid.addWidget(self.dispenser, 1, 1)
        tgrid.addWidget(self.count, 1, 2)
        tgrid.addWidget(send_dispenser, 1, 3)
        self.buttons["correct_member"] = send_member
        self.buttons["correct_dispenser"] = send_dispenser
        layout.addWidget(tower)

        act = QtWidgets.QGroupBox("Set Actuator State (hazardous)")
        grid = QtWidgets.QGridLayout(act)
        self.act_name = QtWidgets.QComboBox()
        self.act_name.addItems(list(defs.actuators))
        self.act_state = QtWidgets.QComboBox()
        self.act_value = QtWidgets.QLineEdit()
        send_act = QtWidgets.QPushButton("Send")
        send_act.setObjectName("command_set_actuator_state")
        send_act.setStyleSheet(HAZARDOUS_BUTTON)
        send_act.clicked.connect(self._send_actuator)
        self.act_name.currentTextChanged.connect(self._actuator_changed)
        self.act_state.currentTextChanged.connect(self._state_changed)
        grid.addWidget(QtWidgets.QLabel("Actuator"), 0, 0)
        grid.addWidget(self.act_name, 0, 1)
        grid.addWidget(QtWidgets.QLabel("State"), 0, 2)
        grid.addWidget(self.act_state, 0, 3)
        grid.addWidget(QtWidgets.QLabel("Value"), 1, 0)
        grid.addWidget(self.act_value, 1, 1, 1, 2)
        grid.addWidget(send_act, 1, 3)
        self.buttons["set_actuator_state"] = send_act
        layout.addWidget(act)
        self._actuator_changed(self.act_name.currentText())

        self.status = QtWidgets.QLabel(disabled_reason or "ready")
        self.status.setObjectName("command_status")
        self.status.setWordWrap(True)
        layout.addWidget(self.status)
        if sender is None:
            for widget in (*self.buttons.values(), bb, tower, act):
                widget.setEnabled(False)

    # -- forms ------------------------------------------------------------------------------
    def _key_changed(self, key: str) -> None:
        """A known key picks its value type and shows its range and meaning."""
        spec = self.keys.get(key.strip())
        if spec is None:
            self.bb_key.setToolTip("")
            return
        self.bb_type.setCurrentText(spec.type)
        limits = (
            f"one of {', '.join(map(str, spec.choices))}"
            if spec.choices is not None
            else " .. ".join("" if v is None else f"{v:g}" for v in (spec.minimum, spec.maximum))
        )
        units = f" {spec.units}" if spec.units else ""
        shown = f"{spec.type}, {limits}{units}" if limits.strip(" .") else spec.type
        self.bb_key.setToolTip(f"{shown}: {spec.meaning}")
        self.bb_value.setPlaceholderText(shown)

    def _actuator_changed(self, name: str) -> None:
        self.act_state.clear()
        actuator = self.defs.actuators.get(name)
        if actuator is not None:
            self.act_state.addItems(list(actuator.states))
        self._state_changed(self.act_state.currentText())

    def _state_changed(self, state: str) -> None:
        """The value box is open only for the states that take a value (the definitions' table)."""
        actuator = self.defs.actuators.get(self.act_name.currentText())
        ranged = actuator is not None and state in actuator.value_states
        self.act_value.setEnabled(ranged)
        self.act_value.clear()
        self.act_value.setPlaceholderText(
            f"{actuator.value_minimum:g} .. {actuator.value_maximum:g} {actuator.unit}"
            if ranged and actuator is not None and actuator.value_minimum is not None
            else "no value for this state"
        )

    def blackboard_params(self) -> dict[str, Any]:
        key = self.bb_key.text().strip()
        if not key:
            raise ParameterError("key: enter a blackboard key")
        return {"key": key, "value": parse_typed_value(self.bb_type.currentText(), self.bb_value.text())}

    def actuator_params(self) -> dict[str, Any]:
        params: dict[str, Any] = {
            "actuator": self.act_name.currentText(),
            "state": self.act_state.currentText(),
        }
        text = self.act_value.text().strip()
        if text and self.act_value.isEnabled():
            try:
                params["value"] = float(text)
            except ValueError:
                raise ParameterError(f"value: {text!r} is not a number") from None
        return params

    def member_params(self) -> dict[str, Any]:
        member = self.member.text().strip()
        if not member:
            raise ParameterError("member: enter a member id")
        return {"key": member_key(member), "value": self.mark.currentText()}

    def dispenser_params(self) -> dict[str, Any]:
        dispenser = self.dispenser.text().strip()
        if not dispenser:
            raise ParameterError("dispenser: enter a dispenser name")
        return {"key": dispenser_key(dispenser), "value": self.count.value()}

    def _send_member(self) -> None:
        try:
            params = self.member_params()
        except ParameterError as exc:
            self._report(f"tower correction not sent: {exc}", error=True)
            return
        self.send("set_blackboard_value", params)

    def _send_dispenser(self) -> None:
        try:
            params = self.dispenser_params()
        except ParameterError as exc:
            self._report(f"dispenser correction not sent: {exc}", error=True)
            return
        self.send("set_blackboard_value", params)

    def _send_blackboard(self) -> None:
        try:
            params = self.blackboard_params()
        except ParameterError as exc:
            self._report(f"set_blackboard_value not sent: {exc}", error=True)
            return
        self.send("set_blackboard_value", params)

    def _send_actuator(self) -> None:
        try:
            params = self.actuator_params()
        except ParameterError as exc:
            self._report(f"set_actuator_state not sent: {exc}", error=True)
            return
        self.send("set_actuator_state", params)

    # -- sending ----------------------------------------------------------------------------
    def _ask(self, cmd: CommandDef, params: Mapping[str, Any]) -> bool:
        shown = ", ".join(f"{k}={v}" for k, v in params.items())
        box = QtWidgets.QMessageBox(
            QtWidgets.QMessageBox.Icon.Warning,
            "Confirm hazardous command",
            f"Send {cmd.name.upper()}{f' ({shown})' if shown else ''}?\n\n{cmd.description}",
            QtWidgets.QMessageBox.StandardButton.Yes | QtWidgets.QMessageBox.StandardButton.No,
            self,
        )
        box.setObjectName("confirm_hazardous")
        box.setDefaultButton(QtWidgets.QMessageBox.StandardButton.No)
        return box.exec() == QtWidgets.QMessageBox.StandardButton.Yes

    def send(self, name: str, params: Mapping[str, Any]) -> Future | None:
        """Send ``name`` (after confirmation if hazardous); return the future, or None if not sent."""
        if self._sender is None:
            return None
        cmd = self.defs.command(name)
        if cmd.hazardous and not self.confirm(cmd, params):
            self._report(f"{name} cancelled by the operator")
            return None
        future = self._sender(name, dict(params))
        self.pending.append((name, future))
        self._report(f"{name} queued")
        return future

    def poll_pending(self) -> None:
        """Report sent commands and the ones the link could not send (called on each refresh)."""
        still = []
        for name, future in self.pending:
            if not future.done():
                still.append((name, future))
                continue
            error = future.exception()
            if error is not None:
                self._report(f"{name} not sent: {error}", error=True)
            else:
                self._report(f"{name} sent (security sequence {future.result().security_seq})")
        self.pending = still

    def _report(self, text: str, error: bool = False) -> None:
        self.status.setText(text)
        self.status.setStyleSheet(f"color: {BAD_COLOUR}; font-weight: bold;" if error else "")


def _completer(words: list[str], parent: QtWidgets.QWidget) -> QtWidgets.QCompleter:
    completer = QtWidgets.QCompleter(words, parent)
    completer.setCaseSensitivity(QtCore.Qt.CaseSensitivity.CaseInsensitive)
    completer.setFilterMode(QtCore.Qt.MatchFlag.MatchContains)
    return completer


__all__ = ["CommandPanel", "ParameterError", "parse_typed_value"]
