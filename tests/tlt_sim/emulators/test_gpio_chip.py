"""The emulated GPIO chip's shared state across processes."""

from __future__ import annotations

import multiprocessing as mp

from tlt_sim.emulators.gpio_chip import EmulatedGpioChip


def _fire(path: str, line: int, pulses: int) -> None:
    chip = EmulatedGpioChip(path)
    for _ in range(pulses):
        chip.drive(line, True)
        chip.drive(line, False)
    chip.close()


def test_pulses_from_another_process_are_counted(tmp_path) -> None:
    path = str(tmp_path / "chip.state")
    twin = EmulatedGpioChip(path)
    proc = mp.get_context("spawn").Process(target=_fire, args=(path, 5, 3))
    proc.start()
    proc.join(timeout=30)
    assert proc.exitcode == 0
    assert twin.poll() == [(5, False, 6)]
    assert twin.edges(5) == 6
    assert twin.poll() == []


def test_private_chip_without_a_file() -> None:
    chip = EmulatedGpioChip(num_lines=4)
    chip.drive(3, True)
    chip.drive(3, True)  # no change, no edge
    assert chip.level(3) and chip.edges(3) == 1
