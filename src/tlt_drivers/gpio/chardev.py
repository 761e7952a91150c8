"""GPIO through the Linux character device (``/dev/gpiochipN``), uAPI v2, for the Jetsons.

``CharDevLines`` requests every configured line in one ``GPIO_V2_GET_LINE_IOCTL`` (inputs and
outputs, each with its active-low and bias flags) and keeps the returned line-request file
descriptor. Reads and writes are ``GPIO_V2_LINE_GET_VALUES_IOCTL`` / ``..._SET_VALUES_IOCTL``
with a mask selecting one line; levels are logical (the kernel applies active-low). Closing the
descriptor releases the lines. Errors from the kernel surface as ``OSError`` naming the chip.
"""

from __future__ import annotations

import fcntl
import os

from . import uapi
from .config import LineSpec

_BIAS = {
    "as_is": 0,
    "pull_up": uapi.FLAG_BIAS_PULL_UP,
    "pull_down": uapi.FLAG_BIAS_PULL_DOWN,
    "disabled": uapi.FLAG_BIAS_DISABLED,
}


def line_flags(spec: LineSpec) -> int:
    """The uAPI v2 flags of one configured line."""
    flags = uapi.FLAG_OUTPUT if spec.direction == "output" else uapi.FLAG_INPUT | _BIAS[spec.bias]
    if spec.active_low:
        flags |= uapi.FLAG_ACTIVE_LOW
    return flags


def request_for(consumer: str, specs: tuple[LineSpec, ...]) -> uapi.LineRequest:
    """The line request for ``specs``, outputs starting at their ``initial`` level."""
    outputs = {i: s.initial for i, s in enumerate(specs) if s.direction == "output"}
    return uapi.build_request(consumer, [s.line for s in specs], [line_flags(s) for s in specs], outputs)


class CharDevLines:
    """Line-level access by index into ``specs`` on one GPIO chip."""

    def __init__(self, chip: str, consumer: str, specs: tuple[LineSpec, ...]) -> None:
        self.chip = chip
        self.specs = specs
        chip_fd = os.open(chip, os.O_RDWR | os.O_CLOEXEC)
        try:
            req = request_for(consumer, specs)
            try:
                fcntl.ioctl(chip_fd, uapi.GPIO_V2_GET_LINE_IOCTL, req)
            except OSError as exc:
                raise OSError(
                    exc.errno, f"{chip}: line request for {[s.line for s in specs]} failed: {exc.strerror}"
                ) from exc
            self._fd = req.fd
        finally:
            os.close(chip_fd)

    def get(self, index: int) -> bool:
        values = uapi.LineValues(bits=0, mask=1 << index)
        fcntl.ioctl(self._fd, uapi.GPIO_V2_LINE_GET_VALUES_IOCTL, values)
        return bool(values.bits & (1 << index))

    def set(self, index: int, level: bool) -> None:
        values = uapi.LineValues(bits=(1 << index) if level else 0, mask=1 << index)
        fcntl.ioctl(self._fd, uapi.GPIO_V2_LINE_SET_VALUES_IOCTL, values)

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1
