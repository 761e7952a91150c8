"""The lifecycle every hardware interface follows, in the manner of ros2_control.

A hardware interface owns one link (a serial port, a socket, a GPIO chip). Its controller-facing
side is two calls made each control cycle: ``read`` (device -> state) and ``write`` (command ->
device). Around them sits the ros2_control lifecycle:

    UNCONFIGURED --configure--> INACTIVE --activate--> ACTIVE
    ACTIVE --deactivate--> INACTIVE --cleanup--> UNCONFIGURED
    any --error in a transition, read or write--> ERROR --recover--> UNCONFIGURED/INACTIVE/ACTIVE

``configure`` opens the link, ``activate`` enables torque or power. An exception from the
subclass's hooks never escapes into the control loop: it moves the interface to ERROR with the
reason in ``fault``, after which ``write`` no longer commands the device until ``recover`` has
brought it back. Subclasses implement the ``on_*`` hooks only.
"""

from __future__ import annotations

import enum
import logging


class Lifecycle(enum.IntEnum):
    """Lifecycle states; values match ``tlt_interfaces/msg/HardwareStatus``."""

    UNCONFIGURED = 0
    INACTIVE = 1
    ACTIVE = 2
    FINALIZED = 3
    ERROR = 4


class HardwareInterface:
    """Base of every driver's hardware interface. Subclasses override the ``on_*`` hooks."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.state = Lifecycle.UNCONFIGURED
        self.fault = ""
        self.errors = 0
        self._log = logging.getLogger(f"tlt.hw.{name}")

    # --- hooks for subclasses -------------------------------------------------------------
    def on_configure(self) -> None:
        """Open the link and check the device answers."""

    def on_activate(self) -> None:
        """Enable torque or power; the device may move after this."""

    def on_deactivate(self) -> None:
        """Stop motion and disable torque or power."""

    def on_cleanup(self) -> None:
        """Close the link."""

    def on_read(self, now: float) -> None:
        """Read the device's state into the interface's state values."""

    def on_write(self, now: float) -> None:
        """Send the interface's command values to the device."""

    # --- lifecycle ----------------------------------------------------------------------------
    def configure(self) -> bool:
        return self._transition("configure", Lifecycle.UNCONFIGURED, Lifecycle.INACTIVE, self.on_configure)

    def activate(self) -> bool:
        return self._transition("activate", Lifecycle.INACTIVE, Lifecycle.ACTIVE, self.on_activate)

    def deactivate(self) -> bool:
        return self._transition("deactivate", Lifecycle.ACTIVE, Lifecycle.INACTIVE, self.on_deactivate)

    def cleanup(self) -> bool:
        return self._transition("cleanup", Lifecycle.INACTIVE, Lifecycle.UNCONFIGURED, self.on_cleanup)

    def shutdown(self) -> None:
        """Leave the device safe and the link closed, from whatever state."""
        for hook in (self.on_deactivate, self.on_cleanup):
            try:
                hook()
            except Exception as exc:  # the device may already be gone; shutting down goes on
                self._log.warning("%s: %s during shutdown: %s", self.name, hook.__name__, exc)
        self.state = Lifecycle.FINALIZED

    def recover(self, *, reactivate: bool = True) -> bool:
        """From ERROR: close the link, open it again and (by default) reactivate."""
        if self.state != Lifecycle.ERROR:
            return self.state != Lifecycle.FINALIZED
        try:
            self.on_cleanup()
        except Exception as exc:  # the link is being reopened anyway
            self._log.info("%s: cleanup before recovery: %s", self.name, exc)
        self.state = Lifecycle.UNCONFIGURED
        if not self.configure():
            return False
        if reactivate and not self.activate():
            return False
        self.fault = ""
        return True

    # --- control cycle --------------------------------------------------------------------------
    def read(self, now: float) -> bool:
        """Read state; on failure go to ERROR. Returns whether the read succeeded."""
        if self.state not in (Lifecycle.INACTIVE, Lifecycle.ACTIVE):
            return False
        return self._guard("read", lambda: self.on_read(now))

    def write(self, now: float) -> bool:
        """Write commands, only while ACTIVE; on failure go to ERROR."""
        if self.state != Lifecycle.ACTIVE:
            return False
        return self._guard("write", lambda: self.on_write(now))

    @property
    def active(self) -> bool:
        return self.state == Lifecycle.ACTIVE

    def set_error(self, reason: str) -> None:
        """Enter ERROR with ``reason``; motion stops being commanded."""
        if self.state != Lifecycle.ERROR:
            self._log.error("%s: %s", self.name, reason)
        self.errors += 1
        self.fault = reason
        self.state = Lifecycle.ERROR

    def _guard(self, what: str, fn) -> bool:
        try:
            fn()
            return True
        except Exception as exc:
            self.set_error(f"{what} failed: {exc}")
            return False

    def _transition(self, what: str, source: Lifecycle, target: Lifecycle, hook) -> bool:
        if self.state != source:
            raise RuntimeError(f"{self.name}: cannot {what} from {self.state.name}")
        if self._guard(what, hook):
            self.state = target
            return True
        return False


class JointGroupInterface(HardwareInterface):
    """A hardware interface over named joints (a servo chain): ``read`` fills ``position``,
    ``write`` sends ``command``, both keyed by joint name."""

    position: dict[str, float]
    command: dict[str, float]
