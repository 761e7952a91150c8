"""``tlt twin run``: the EDU's digital twin as one ROS process behind the real driver links.

Loads ``config/twin/edu.yaml`` (the machine), a mission and an optional scenario, builds the MuJoCo
scene and hosts every device emulator bound to it (:mod:`tlt_sim.twin.devices`): the lifter
firmware, the Dynamixel and MightyZAP chains on pseudo-terminals linked at
``$TLT_RUN_DIR/<component>``, the two UR controllers on their loopback addresses, the EE GPIO chips.
The driver nodes open those links exactly as they open the stand-alone emulators or the hardware.
Once everything answers, the file ``$TLT_RUN_DIR/twin.ready`` appears (launch sets wait on it).

The twin owns time: it publishes ``/clock`` and steps at ``--rtf`` (1 by default, 0 = as fast as
the CPU allows); the drivers run with ``use_sim_time``. Cameras and ground truth are published
on demand (:mod:`tlt_sim.twin.ros_streams`), the cameras through the sensor models of
``config/twin/cameras.yaml`` (depth noise and holes, image noise and exposure, mount errors:
:mod:`tlt_sim.model.camera_sensor`; ``--camera-model exact`` for the exact render, for
diagnosis), by the light of ``config/twin/lighting.yaml`` (``--lighting lunar``: a low, hard
sun). Runs until SIGINT/SIGTERM or ``--duration`` seconds of sim time, then withdraws its links.
``--viewer`` (or ``viewer.enabled`` in ``run.yaml``) opens MuJoCo's viewer window on the running
model for people (:mod:`tlt_sim.twin.viewer`); without a display the twin refuses to start.
Exit status 0, or 2 for a bad configuration or no viewer.

    python -m tlt_sim.twin.main --scenario config/twin/scenarios/device_faults.yaml --rtf 0
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import logging
import os
import sys
import time
from pathlib import Path

import mujoco

from tlt_common.config_schema import ConfigError
from tlt_common.ros.interpreter_lock import share_the_interpreter_quickly
from tlt_common.ros.stop_signals import stop_on_signals
from tlt_drivers.gpio.config import run_dir as default_run_dir
from tlt_sim.model import names
from tlt_sim.model.camera_sensor import DEFAULT_CAMERAS, load_camera_sensors, offset_mounts
from tlt_sim.model.config import DEFAULT_EDU
from tlt_sim.model.lighting import apply_lighting, load_lighting
from tlt_sim.model.scene import ModelCompileError, Scene
from tlt_sim.twin.pacing import Pacer
from tlt_sim.twin.settings import DEFAULT_SETTINGS, load_settings
from tlt_sim.twin.simulation import Twin
from tlt_sim.twin.viewer import ViewerSync, ViewerUnavailable, open_viewer, probe

READY_FILE = "twin.ready"
# Wall time the loop sleeps at least per sync period, so that the pty and socket threads answer
# the drivers within their serial timeouts even at --rtf 0 (they share the interpreter's lock).
YIELD_S = 0.001
log = logging.getLogger("tlt.twin")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="tlt twin run", description=__doc__.splitlines()[0])
    p.add_argument("--edu", type=Path, default=DEFAULT_EDU, help="machine description (edu.yaml)")
    p.add_argument("--mission", type=Path, help="mission YAML (default: the one edu.yaml names)")
    p.add_argument("--scenario", help="scenario YAML (config/twin/scenarios/); empty for none")
    p.add_argument("--settings", type=Path, default=DEFAULT_SETTINGS, help="run settings (run.yaml)")
    p.add_argument(
        "--cameras",
        type=Path,
        default=DEFAULT_CAMERAS,
        help="what the cameras make of the render (cameras.yaml)",
    )
    p.add_argument(
        "--lighting",
        help="a preset of config/twin/lighting.yaml (lunar: a low, hard sun), or "
        "`model` for the model's own lights; default: the file's `lighting`",
    )
    p.add_argument(
        "--camera-model",
        choices=("realistic", "exact"),
        help="exact: the render's colours and depth, cameras exactly on their mounts (for "
        "diagnosis); default: cameras.yaml's `realistic`",
    )
    p.add_argument("--rtf", type=float, help="real-time factor (0: as fast as possible)")
    p.add_argument(
        "--run-dir", type=Path, help="where device links go (default $TLT_RUN_DIR or /tmp/tlt-run)"
    )
    p.add_argument("--ur-x-host", help="loopback address of ARS X's UR controller")
    p.add_argument("--ur-y-host", help="loopback address of ARS Y's UR controller")
    p.add_argument("--camera-rate", type=float, help="camera frames per simulated second")
    p.add_argument("--final-png", type=Path, help="on the way out, a PNG of the scene as it stands")
    p.add_argument("--duration", type=float, default=0.0, help="stop after this much sim time (0: never)")
    p.add_argument(
        "--viewer",
        action="store_true",
        default=None,
        help="open MuJoCo's viewer window on the running twin (needs a display)",
    )
    return p


def _write_final_png(scene, path: Path) -> None:
    from tlt_sim.model.render_png import overview_camera, write_png

    try:
        if write_png(scene, overview_camera(scene), path):
            log.info("the scene as it stands: %s", path)
        else:
            log.warning("cannot write %s", path)
    except Exception as exc:  # a renderer that fails must not cost the run its clean shutdown
        log.warning("no final picture: %s", exc)


def main(argv: list[str] | None = None) -> int:
    """Run the twin until a signal or ``--duration``. Returns the exit status."""
    import rclpy

    argv = list(sys.argv[1:] if argv is None else argv)
    args = _parser().parse_args(rclpy.utilities.remove_ros_args(["twin", *argv])[1:])
    logging.basicConfig(level=logging.INFO, format="twin: %(message)s", stream=sys.stdout, force=True)
    try:
        settings = load_settings(args.settings)
        sensors = load_camera_sensors(args.cameras)
        lighting = load_lighting(name=args.lighting)
        if args.camera_model:
            sensors = dataclasses.replace(sensors, realistic=args.camera_model == "realistic")
        changes: dict = {}
        if args.rtf is not None:
            if args.rtf < 0:
                raise ConfigError("--rtf", "", f"must be >= 0, got {args.rtf}")
            changes["rtf"] = args.rtf
        if args.camera_rate is not None:
            if args.camera_rate <= 0:
                raise ConfigError("--camera-rate", "", f"must be > 0, got {args.camera_rate}")
            changes["camera_rate_hz"] = args.camera_rate
        hosts = dict(settings.ur_hosts)
        hosts.update({k: v for k, v in (("ur_x", args.ur_x_host), ("ur_y", args.ur_y_host)) if v})
        if args.viewer:
            changes["viewer"] = True
        settings = settings.replace(ur_hosts=hosts, **changes)
        if settings.viewer:
            probe()  # refuse before anything is built or served
        # An empty --scenario (a launch set's unset variable) means the nominal run.
        scene = Scene(args.edu, args.mission, args.scenario or None)
        apply_lighting(scene.model, lighting)
        if sensors.realistic:
            offset_mounts(scene.model, sensors, names.cameras())
            mujoco.mj_forward(scene.model, scene.data)
        run_dir = args.run_dir or default_run_dir()
        twin = Twin(scene, settings, run_dir)
    except ViewerUnavailable as exc:
        print(f"tlt twin run: no viewer: {exc}", file=sys.stderr)
        return 2
    except (ConfigError, ModelCompileError, ValueError) as exc:
        print(f"tlt twin run: {exc}", file=sys.stderr)
        return 2
    view: ViewerSync | None = None
    if settings.viewer:
        try:
            view = open_viewer(scene.model, scene.data, settings.viewer_rate_hz, scene.edu["render"])
        except ViewerUnavailable as exc:
            twin.close()
            scene.close()
            print(f"tlt twin run: no viewer: {exc}", file=sys.stderr)
            return 2

    # rclpy's own handler would invalidate the context under a publish in the loop: the loop stops
    # on a flag instead.
    stop = stop_on_signals()
    from tlt_common.ros.lean_node import LeanNode
    from tlt_common.ros.rosout_logging import forward_logging_to_rosout, init_rclpy

    init_rclpy(["twin", *argv], signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    from tlt_sim.twin.live_view import LiveView
    from tlt_sim.twin.ros_streams import CameraStreams, ClockPublisher, GroundTruth

    node = LeanNode("twin")
    logs = forward_logging_to_rosout(node)
    ready = Path(run_dir) / READY_FILE
    try:
        clock = ClockPublisher(node)
        cameras = CameraStreams(node, scene, settings, sensors)
        truth = GroundTruth(node, scene, settings.ground_truth_rate_hz)
        live = LiveView(node, scene, settings.tf_rate_hz)
        try:
            twin.start()
        except OSError as exc:  # a UR address already served by another emulator, a pty refused
            print(f"tlt twin run: cannot serve the device links: {exc}", file=sys.stderr)
            return 1
        clock.publish(scene.time)
        ready.write_text(f"{os.getpid()}\n")
        log.info(
            "links up in %s (rtf %s, scenario %s, %s cameras)",
            run_dir,
            settings.rtf or "max",
            scene.scenario.name,
            "realistic" if sensors.realistic else "exact",
        )
        # Hand the interpreter lock to a device thread quickly when one has bytes to answer.
        share_the_interpreter_quickly()
        pacer = Pacer(settings.rtf, min_sleep_s=YIELD_S)
        pacer.rebase(scene.time)
        wall0 = time.monotonic()
        while not stop and rclpy.ok():
            if twin.hold_for_drivers():
                pacer.rebase(scene.time)
            t = twin.tick()
            clock.publish(t)
            cameras.publish_due(t)
            truth.publish_due(t)
            live.publish_due(t)
            if view is not None:
                view.maybe_sync()
            pacer.wait(t)
            if args.duration and t >= args.duration - 1e-9:
                break
        wall = time.monotonic() - wall0
        log.info(
            "stopped at %.2f s of sim time after %.2f s of wall time (%.2fx), %d waits for drivers",
            scene.time,
            wall,
            scene.time / wall if wall > 0 else 0.0,
            twin.holds,
        )
        if args.final_png:
            _write_final_png(scene, args.final_png)
    finally:
        with contextlib.suppress(FileNotFoundError):
            ready.unlink()
        if view is not None:
            view.close()
        twin.close()
        scene.close()
        logs.remove()
        node.destroy_node()
        if rclpy.ok():
            rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
