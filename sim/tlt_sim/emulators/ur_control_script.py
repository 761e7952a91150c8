"""The command protocol of ur-rtde's control script, executed on the emulated arm.

``RTDEControlInterface`` uploads a URScript program that loops once per controller cycle: it
reads a command code from input int register 0 (plus the register offset), its parameters from
input int/double registers, executes it and answers through output int register 0 (1 = ready for
a command, 2 = done with the command). The client then writes command 0, and the script answers
ready again. Streaming commands (servoJ, speedJ, ...) are acknowledged with "ready" at once.
Output int register 2 carries the progress word of asynchronous moves (bit 15: running, bits
16-23: change counter, bits 24-30: operation id).

This module does not interpret URScript: it executes the same register protocol in Python,
one ``tick`` per controller cycle. A command this emulator does not implement stops the program
with an error (as a URScript runtime error would), so the client sees the call fail instead of a
silent success.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from tlt_sim.emulators import ur_kinematics as kin
from tlt_sim.emulators.ur_arm import UR10eArm

log = logging.getLogger("tlt.sim.ur.script")

READY = 1
DONE = 2

MOVEJ, MOVEJ_IK, MOVEL, MOVEL_FK = 1, 2, 3, 4
SPEEDJ, SERVOJ = 9, 11
SPEED_STOP, SERVO_STOP, SET_PAYLOAD = 15, 16, 17
GET_STEPTIME, SET_TCP, GET_IK_ARGS, PROTECTIVE_STOP = 26, 29, 30, 31
STOPL, STOPJ, GET_TCP_OFFSET = 33, 34, 40
GET_FK_DEFAULT, GET_FK_ARGS, GET_IK_DEFAULT, IS_STEADY = 43, 44, 46, 47
IK_HAS_SOLUTION_DEFAULT, IK_HAS_SOLUTION_ARGS = 60, 61
STOP_SCRIPT = 255
# Commands the script processes without the ready/done handshake (it signals ready right away).
STREAMING = frozenset({9, 10, 11, 24, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71})


class Registers:
    """The 48 general-purpose int and double registers in each direction."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.in_int = [0] * 48
        self.in_double = [0.0] * 48
        self.out_int = [0] * 48
        self.out_double = [0.0] * 48


class ControlScript:
    """The running rtde_control program: ``tick()`` once per controller cycle."""

    def __init__(
        self,
        arm: UR10eArm,
        registers: Registers,
        *,
        offset: int = 0,
        step_time: float = 0.002,
        on_protective_stop: Callable[[str], None] | None = None,
    ) -> None:
        self.arm = arm
        self.reg = registers
        self.offset = offset
        self.step_time = step_time
        self.on_protective_stop = on_protective_stop
        self.running = True
        self.error = ""
        self.commands_executed = 0
        self._executing = False
        self._waiting: Callable[[], bool] | None = None
        self._async_move = False
        self._op_id = 0
        self._change_count = 0
        self.payload = (0.0, [0.0, 0.0, 0.0])
        self._write_progress(-1)
        self._out_int(0, READY)

    # --- register helpers ---------------------------------------------------------------------
    def _in_int(self, i: int) -> int:
        return self.reg.in_int[i + self.offset]

    def _in_double(self, i: int) -> float:
        return self.reg.in_double[i + self.offset]

    def _in_vec(self, first: int, n: int = 6) -> list[float]:
        return [self._in_double(first + k) for k in range(n)]

    def _out_int(self, i: int, value: int) -> None:
        self.reg.out_int[i + self.offset] = value

    def _out_vec(self, values: list[float]) -> None:
        for k, v in enumerate(values):
            self.reg.out_double[k + self.offset] = float(v)

    def _write_progress(self, value: int) -> None:
        self._change_count = (self._change_count + 1) % 128
        if value == 0:
            self._op_id = (self._op_id + 1) % 128
        word = (self._change_count << 16) | (self._op_id << 24)
        if value >= 0:
            word |= 0x8000 | min(value, 0x7FFF)
        self._out_int(2, word)

    # --- the main loop, one cycle ------------------------------------------------------------
    def tick(self) -> None:
        """One pass of the script's main loop."""
        if not self.running:
            return
        with self.reg.lock:
            if self._async_move and not self.arm.moving:
                self._async_move = False
                self._write_progress(-1)
            if self._waiting is not None:
                if not self._waiting():
                    return
                self._waiting = None
                self._out_int(0, DONE)
                return
            cmd = self._in_int(0)
            if cmd in STREAMING:
                self._process(cmd)
                if self.running:
                    self._out_int(0, READY)
            elif cmd == 0:
                self._executing = False
                self._out_int(0, READY)
            elif not self._executing:
                self._executing = True
                self._process(cmd)
                if self.running and self._waiting is None:
                    self._out_int(0, DONE)

    def abort(self, reason: str) -> None:
        """The program stops (protective stop, stop request, runtime error)."""
        if self.running:
            log.info("control program stopped: %s", reason)
        self.running = False
        self.error = reason
        self._waiting = None

    # --- commands --------------------------------------------------------------------------
    def _process(self, cmd: int) -> None:
        self.commands_executed += 1
        try:
            self._dispatch(cmd)
        except (ValueError, kin.IKError) as exc:
            self.abort(f"runtime error in command {cmd}: {exc}")

    def _dispatch(self, cmd: int) -> None:
        arm = self.arm
        if cmd in (MOVEJ, MOVEJ_IK, MOVEL, MOVEL_FK):
            target = self._in_vec(0)
            v, a, asynchronous = self._in_double(6), self._in_double(7), self._in_int(1) == 1
            self._stop_async_move()
            if cmd == MOVEJ_IK:
                target = kin.inverse_nearest(target, arm.positions(), arm.tcp)
            if cmd == MOVEL_FK:
                target = kin.forward(target, arm.tcp)
            if cmd in (MOVEJ, MOVEJ_IK):
                arm.move_joints(target, v, a)
            else:
                arm.move_linear(target, v, a)
            if asynchronous:
                self._async_move = True
                self._write_progress(0)
            else:
                self._waiting = lambda: not arm.moving
        elif cmd == SPEEDJ:
            arm.speed(self._in_vec(0), self._in_double(6))
        elif cmd == SERVOJ:
            arm.servo(self._in_vec(0), self._in_double(9), self._in_double(10))
        elif cmd in (SPEED_STOP, SERVO_STOP):
            arm.stop(self._in_double(0))
        elif cmd in (STOPJ, STOPL):
            self._stop_async_move()
            arm.stop(self._in_double(0))
            if self._in_int(1) == 1:
                self._async_move = arm.moving
                self._write_progress(0)
            else:
                self._waiting = lambda: not arm.moving
        elif cmd == SET_PAYLOAD:
            self.payload = (self._in_double(0), self._in_vec(1, 3))
        elif cmd == GET_STEPTIME:
            self.reg.out_double[self.offset] = self.step_time
        elif cmd == SET_TCP:
            arm.set_tcp(self._in_vec(0))
        elif cmd == GET_TCP_OFFSET:
            self._out_vec(arm.tcp)
        elif cmd == GET_FK_DEFAULT:
            self._out_vec(arm.tcp_pose())
        elif cmd == GET_FK_ARGS:
            self._out_vec(kin.forward(self._in_vec(0), self._in_vec(6)))
        elif cmd == GET_IK_DEFAULT:
            self._out_vec(kin.inverse_nearest(self._in_vec(0), arm.positions(), arm.tcp))
        elif cmd == GET_IK_ARGS:
            self._out_vec(kin.inverse_nearest(self._in_vec(0), self._in_vec(6), arm.tcp))
        elif cmd in (IK_HAS_SOLUTION_DEFAULT, IK_HAS_SOLUTION_ARGS):
            self._out_int(1, 1 if kin.inverse_all(self._in_vec(0), arm.tcp) else 0)
        elif cmd == IS_STEADY:
            self._out_int(1, 0 if arm.moving else 1)
        elif cmd == PROTECTIVE_STOP:
            if self.on_protective_stop is not None:
                self.on_protective_stop("protective_stop() requested by the control script")
        elif cmd == STOP_SCRIPT:
            self.abort("stop requested by the client")
        else:
            self.abort(f"command {cmd} is not implemented by the emulator")

    def _stop_async_move(self) -> None:
        if self._async_move:
            self._async_move = False
            self._write_progress(-1)
