"""Real-time factor of the MuJoCo twin, and the cost of a rendered camera frame.

Runs the full EDU scene (both UR10e arms moving through their joint ranges at rated speed,
Top Grippers holding the payload) for a stretch of simulated time and prints, measured side by
side in one run:

* the real-time factor without cameras (goal >= 20x),
* the real-time factor with one D405 streaming RGB, depth and segmentation at 320x240, 10 Hz of
  simulated time (goal >= 2x),
* milliseconds per rendered RGB-D-segmentation frame at 320x240 and 640x480 (multisampled, the
  default, and at 320x240 also without multisampling),
* the CPU cost of one sync period of the twin process's loop (``Twin.tick``: every device
  emulator advanced, bound to the model, the model stepped, fed back), with no driver attached,
  which bounds the real-time factor ``tlt twin run`` can reach.

Each real-time factor is measured ``--repeat`` times (3 by default) and printed as the median with
the range: on a shared machine the wall-clock figures swing with other work, the CPU-time figures
(this process's CPU seconds, including OSMesa's threads) much less.

Usage: python bench/twin_rtf.py [--seconds S] [--repeat N] [--timestep DT ...]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from tlt_sim.model import names
from tlt_sim.model.scene import Scene
from tlt_sim.twin.settings import load_settings
from tlt_sim.twin.simulation import Twin


def _swing(scene: Scene, t: float) -> None:
    """Both arms sweep every joint back and forth, flipping direction each second."""
    sign = 1.0 if int(t) % 2 == 0 else -1.0
    for arm in names.ARMS:
        for i, joint in enumerate(names.arm_joints(arm)):
            scene.command_velocity(joint, sign * (0.6 if i < 3 else 1.0))


def run(scene: Scene, seconds: float, camera: str | None, rate_hz: float = 10.0) -> tuple[float, float, int]:
    """Simulate ``seconds``; return the real-time factor by wall clock and by this process's CPU
    time (the second is steadier on a shared machine), and the number of frames rendered."""
    scene.reset()
    control_steps = max(1, round(0.02 / scene.timestep))  # a 50 Hz controller feeds the arms
    frame_period = 1.0 / rate_hz
    next_frame, frames, steps = 0.0, 0, round(seconds / scene.timestep)
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(0, steps, control_steps):
        _swing(scene, scene.time)
        scene.step(control_steps)
        if camera and scene.time >= next_frame:
            scene.render(camera, 320, 240)
            frames += 1
            next_frame += frame_period
    return seconds / (time.perf_counter() - wall), seconds / (time.process_time() - cpu), frames


def frame_ms(
    scene: Scene,
    camera: str,
    width: int,
    height: int,
    depth: bool = True,
    segmentation: bool = True,
    count: int = 20,
    antialias: bool = True,
) -> tuple[float, float]:
    """Milliseconds per frame, by wall clock and by CPU time."""
    # The first frame pays for the GL context and textures.
    scene.render(camera, width, height, antialias=antialias)
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(count):
        scene.render(camera, width, height, depth, segmentation, antialias=antialias)
    return (time.perf_counter() - wall) / count * 1000.0, (time.process_time() - cpu) / count * 1000.0


def twin_period_ms(seconds: float, repeat: int) -> list[float]:
    """CPU milliseconds of the simulation thread per sync period of a :class:`Twin` (all emulators,
    UR controllers in their child processes, no driver talking), one figure per repeat."""
    settings = load_settings().replace(ur_hosts={"ur_x": "127.0.76.2", "ur_y": "127.0.76.3"})
    with tempfile.TemporaryDirectory(prefix="tlt-bench-") as tmp:
        scene = Scene(out_dir=Path(tmp) / "model")
        twin = Twin(scene, settings, Path(tmp) / "run")
        try:
            twin.start()
            twin.run_for(0.2)  # links up, first commands settled
            periods = max(1, round(seconds / settings.sync_period_s))
            out = []
            for _ in range(repeat):
                cpu = time.thread_time()
                twin.run_for(periods * settings.sync_period_s)
                out.append((time.thread_time() - cpu) / periods * 1000.0)
            return out
        finally:
            twin.close()
            scene.close()


def _spread(values: list[float]) -> str:
    return f"{statistics.median(values):6.1f}x ({min(values):.1f}-{max(values):.1f})"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=5.0, help="simulated seconds per measurement")
    p.add_argument("--repeat", type=int, default=3, help="measurements per figure (median and range)")
    p.add_argument(
        "--timestep",
        type=float,
        action="append",
        help="physics step, s (repeatable; default: edu.yaml's and 4 ms)",
    )
    args = p.parse_args()
    camera = names.d405_camera("ars_x", "a")
    timesteps = args.timestep or [None, 0.004]
    print("real-time factors: wall clock / CPU time of this process (the machine may be shared)")
    for dt in timesteps:
        with Scene(timestep=dt) as scene:
            scene.render(camera, 320, 240)  # make the GL context outside the timed runs
            m = scene.model
            print(
                f"\nscene: {m.nbody} bodies, {m.nv} dofs, {m.nu} actuators, {m.neq} equality constraints,"
                f" timestep {scene.timestep * 1000:.1f} ms"
            )
            runs = [run(scene, args.seconds, None) for _ in range(max(1, args.repeat))]
            print(
                f"  both arms moving, no camera:           wall {_spread([r[0] for r in runs])}"
                f"  CPU {_spread([r[1] for r in runs])}   (goal >= 20x)"
            )
            runs = [run(scene, args.seconds, camera) for _ in range(max(1, args.repeat))]
            print(
                f"  + one D405 320x240 RGB-D-seg at 10 Hz: wall {_spread([r[0] for r in runs])}"
                f"  CPU {_spread([r[1] for r in runs])}   (goal >= 2x, {runs[0][2]} frames each)"
            )
    with Scene() as scene:
        for w, h in ((320, 240), (640, 480)):
            wall, cpu = frame_ms(scene, camera, w, h)
            print(f"ms per RGB-D-segmentation frame {w}x{h}:  {wall:6.1f} / {cpu:6.1f}")
        wall, cpu = frame_ms(scene, camera, 320, 240, depth=False, segmentation=False)
        print(f"ms per RGB frame 320x240:                   {wall:6.1f} / {cpu:6.1f}")
        wall, cpu = frame_ms(scene, camera, 320, 240, antialias=False)
        print(
            f"  the same RGB-D-seg 320x240, no antialiasing: {wall:6.1f} / {cpu:6.1f}"
            "  (run.yaml cameras.antialias: false)"
        )
    ms = twin_period_ms(min(args.seconds, 2.0), max(1, args.repeat))
    period_ms = load_settings().sync_period_s * 1000.0
    print(
        f"twin process, CPU ms per {period_ms:.0f} ms sync period (no drivers): {statistics.median(ms):.2f}"
        f" ({min(ms):.2f}-{max(ms):.2f}), at most {period_ms / statistics.median(ms):.1f}x of real time"
    )


if __name__ == "__main__":
    main()
