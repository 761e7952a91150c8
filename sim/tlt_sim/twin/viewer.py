"""An optional window on the running twin for people (``tlt twin run --viewer``).

MuJoCo's passive viewer (:func:`mujoco.viewer.launch_passive`) draws the twin's own model and data
in a window of its own thread; the simulation loop stays in charge of stepping. :class:`ViewerSync`
hands the viewer the present state at most ``rate_hz`` times per wall second (30 by default), so a
person sees smooth motion while the physics pays for one state copy per frame, not per step.
``Handle.sync`` takes the viewer's lock itself while it copies (the render thread draws only from
that copy), so the loop must not hold the lock around it. Closing the window leaves the twin
running; stopping the twin closes the window.

Where no window can open (no ``DISPLAY`` / ``WAYLAND_DISPLAY``, GLFW missing or refusing the
display), :func:`probe` raises :class:`ViewerUnavailable` with a one-line reason before anything
is started, and ``tlt twin run`` exits with status 2.
"""

from __future__ import annotations

import logging
import os
import threading
import time
import warnings
from collections.abc import Callable, Mapping
from typing import Any, Protocol

log = logging.getLogger("tlt.twin")

# Wall seconds to wait for the viewer's window thread to hand back its handle: a window that fails
# to open inside that thread would otherwise leave the caller waiting for ever.
OPEN_TIMEOUT_S = 10.0


class ViewerUnavailable(RuntimeError):
    """No viewer window can be opened here; the message is a one-line reason."""


class ViewerHandle(Protocol):
    """What :class:`ViewerSync` uses of ``mujoco.viewer.Handle``."""

    def is_running(self) -> bool: ...

    def sync(self) -> None: ...

    def close(self) -> None: ...

    def lock(self) -> Any: ...


def display_problem(environ: Mapping[str, str] | None = None) -> str | None:
    """Why no window can open in ``environ`` (the process's by default), or None if a display is named."""
    env = os.environ if environ is None else environ
    if env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"):
        return None
    return "no display to open a window on (neither DISPLAY nor WAYLAND_DISPLAY is set)"


def probe(environ: Mapping[str, str] | None = None) -> None:
    """Check that a viewer window can open: a display is named, MuJoCo's viewer imports and GLFW
    starts on that display. Raises :class:`ViewerUnavailable` with the reason otherwise."""
    problem = display_problem(environ)
    if problem:
        raise ViewerUnavailable(problem)
    try:
        import glfw
        import mujoco.viewer  # noqa: F401  (fails here when GLFW's library is missing)
    except (ImportError, RuntimeError, OSError) as exc:
        raise ViewerUnavailable(f"MuJoCo's viewer cannot load: {exc}") from exc
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        started = glfw.init()
    if not started:
        _code, description = glfw.get_error()
        if isinstance(description, bytes):
            description = description.decode(errors="replace")
        detail = description or "; ".join(str(w.message) for w in caught) or "no reason given"
        raise ViewerUnavailable(f"GLFW cannot open the display: {detail}")


class ViewerSync:
    """Hands the simulation's state to a viewer handle at most ``rate_hz`` times per wall second.

    Call :meth:`maybe_sync` from the simulation thread after each sync period; it returns True when
    it copied the state. Once the person closes the window it does nothing more (logged once).
    ``clock`` is injectable for tests.
    """

    def __init__(
        self, handle: ViewerHandle, rate_hz: float = 30.0, clock: Callable[[], float] = time.monotonic
    ) -> None:
        if rate_hz <= 0:
            raise ValueError(f"viewer rate must be > 0, got {rate_hz}")
        self.handle = handle
        self.period = 1.0 / rate_hz
        self.clock = clock
        self.syncs = 0
        self._next = clock()
        self._open = True

    @property
    def open(self) -> bool:
        return self._open

    def maybe_sync(self) -> bool:
        if not self._open:
            return False
        now = self.clock()
        if now < self._next:
            return False
        if not self.handle.is_running():
            self._open = False
            log.info("viewer window closed; the twin runs on")
            return False
        self.handle.sync()  # takes the viewer's lock while it copies model and data
        self.syncs += 1
        # No catching up after a slow period: the next frame is one period from now.
        self._next += self.period
        if self._next <= now:
            self._next = now + self.period
        return True

    def close(self) -> None:
        """Close the window (if still open); safe to call more than once."""
        if self._open:
            self._open = False
            self.handle.close()


def open_viewer(
    model: Any,
    data: Any,
    rate_hz: float = 30.0,
    view: Mapping[str, Any] | None = None,
    timeout_s: float = OPEN_TIMEOUT_S,
    launch: Callable[..., ViewerHandle] | None = None,
) -> ViewerSync:
    """Open MuJoCo's passive viewer on ``model`` and ``data`` (call :func:`probe` first).

    ``view`` (``lookat``, ``distance``, ``azimuth``, ``elevation``: ``edu.yaml``'s ``render``
    section) places the window's free camera where the overview picture looks from. ``launch``
    defaults to ``mujoco.viewer.launch_passive``. Raises :class:`ViewerUnavailable` when the window
    does not open within ``timeout_s`` or the launch fails.
    """
    if launch is None:
        import mujoco.viewer

        launch = mujoco.viewer.launch_passive
    result: list[Any] = []

    def _launch() -> None:
        try:
            result.append(launch(model, data, show_left_ui=False, show_right_ui=False))
        except Exception as exc:  # reported to the caller below
            result.append(exc)

    opener = threading.Thread(target=_launch, name="viewer-open", daemon=True)
    opener.start()
    opener.join(timeout_s)
    if not result:
        raise ViewerUnavailable(f"the viewer window did not open within {timeout_s:g} s")
    if isinstance(result[0], Exception):
        raise ViewerUnavailable(f"the viewer window did not open: {result[0]}")
    handle = result[0]
    if view is not None:
        with handle.lock():  # the window's thread reads the camera while it draws
            cam = handle.cam
            cam.lookat[:] = view["lookat"]
            cam.distance = view["distance"]
            cam.azimuth = view["azimuth"]
            cam.elevation = view["elevation"]
    return ViewerSync(handle, rate_hz)


__all__ = ["OPEN_TIMEOUT_S", "ViewerSync", "ViewerUnavailable", "display_problem", "open_viewer", "probe"]
