"""The ctypes layout of the GPIO v2 uAPI against the kernel header, and line requests built on it."""

from __future__ import annotations

import ctypes
import subprocess

import pytest

from tlt_drivers.gpio import uapi
from tlt_drivers.gpio.chardev import line_flags, request_for
from tlt_drivers.gpio.config import LineSpec

_PROBE = r"""
#include <stdio.h>
#include <stddef.h>
#include <linux/gpio.h>
int main(void) {
  printf("%zu %zu %zu %zu %zu %zu\n", sizeof(struct gpio_v2_line_request), sizeof(struct gpio_v2_line_config),
         sizeof(struct gpio_v2_line_config_attribute), sizeof(struct gpio_v2_line_attribute),
         sizeof(struct gpio_v2_line_values), sizeof(struct gpiochip_info));
  printf("%zu %zu %zu %zu %zu\n", offsetof(struct gpio_v2_line_request, consumer),
         offsetof(struct gpio_v2_line_request, config), offsetof(struct gpio_v2_line_request, num_lines),
         offsetof(struct gpio_v2_line_request, fd), offsetof(struct gpio_v2_line_config, attrs));
  printf("%lu %lu %lu %lu %lu\n", (unsigned long)GPIO_V2_GET_LINE_IOCTL,
         (unsigned long)GPIO_V2_LINE_SET_CONFIG_IOCTL, (unsigned long)GPIO_V2_LINE_GET_VALUES_IOCTL,
         (unsigned long)GPIO_V2_LINE_SET_VALUES_IOCTL,
         (unsigned long)GPIO_GET_CHIPINFO_IOCTL);
  printf("%d %d %d %d %d\n", (int)GPIO_V2_LINE_FLAG_ACTIVE_LOW, (int)GPIO_V2_LINE_FLAG_INPUT,
         (int)GPIO_V2_LINE_FLAG_OUTPUT, (int)GPIO_V2_LINE_FLAG_BIAS_PULL_UP,
         (int)GPIO_V2_LINE_ATTR_ID_OUTPUT_VALUES);
  return 0;
}
"""


def test_sizes_and_ioctl_numbers_match_the_published_abi() -> None:
    # Values of the 64-bit Linux ABI (sizes from linux/gpio.h; ioctl numbers as _IOWR builds them).
    assert ctypes.sizeof(uapi.LineRequest) == 592
    assert ctypes.sizeof(uapi.LineConfig) == 272
    assert ctypes.sizeof(uapi.LineValues) == 16
    assert ctypes.sizeof(uapi.ChipInfo) == 68
    assert uapi.GPIO_V2_GET_LINE_IOCTL == 0xC250B407
    assert uapi.GPIO_V2_LINE_GET_VALUES_IOCTL == 0xC010B40E
    assert uapi.GPIO_V2_LINE_SET_VALUES_IOCTL == 0xC010B40F
    assert uapi.GPIO_GET_CHIPINFO_IOCTL == 0x8044B401


def test_layout_matches_the_kernel_header_compiled_here(tmp_path) -> None:
    src = tmp_path / "probe.c"
    src.write_text(_PROBE)
    subprocess.run(["cc", "-o", str(tmp_path / "probe"), str(src)], check=True, timeout=60)
    out = subprocess.run([str(tmp_path / "probe")], check=True, capture_output=True, text=True).stdout
    sizes, offsets, ioctls, flags = ([int(v) for v in line.split()] for line in out.splitlines())
    assert sizes == [
        ctypes.sizeof(uapi.LineRequest),
        ctypes.sizeof(uapi.LineConfig),
        ctypes.sizeof(uapi.LineConfigAttribute),
        ctypes.sizeof(uapi.LineAttribute),
        ctypes.sizeof(uapi.LineValues),
        ctypes.sizeof(uapi.ChipInfo),
    ]
    assert offsets == [
        uapi.LineRequest.consumer.offset,
        uapi.LineRequest.config.offset,
        uapi.LineRequest.num_lines.offset,
        uapi.LineRequest.fd.offset,
        uapi.LineConfig.attrs.offset,
    ]
    assert ioctls == [
        uapi.GPIO_V2_GET_LINE_IOCTL,
        uapi.GPIO_V2_LINE_SET_CONFIG_IOCTL,
        uapi.GPIO_V2_LINE_GET_VALUES_IOCTL,
        uapi.GPIO_V2_LINE_SET_VALUES_IOCTL,
        uapi.GPIO_GET_CHIPINFO_IOCTL,
    ]
    assert flags == [
        uapi.FLAG_ACTIVE_LOW,
        uapi.FLAG_INPUT,
        uapi.FLAG_OUTPUT,
        uapi.FLAG_BIAS_PULL_UP,
        uapi.ATTR_ID_OUTPUT_VALUES,
    ]


def test_request_groups_flags_and_sets_initial_outputs() -> None:
    specs = (
        LineSpec("gun_left", 12, "output", initial=False),
        LineSpec("gun_right", 13, "output", initial=True),
        LineSpec("switch", 40, "input", active_low=True, bias="pull_up"),
    )
    req = request_for("tlt-ee-x", specs)
    raw = bytes(req)
    assert len(raw) == 592
    assert list(req.offsets[:3]) == [12, 13, 40] and req.num_lines == 3
    assert req.consumer == b"tlt-ee-x"
    assert req.config.num_attrs == 3
    attrs = [req.config.attrs[i] for i in range(3)]
    assert (attrs[0].attr.id, attrs[0].attr.value.flags, attrs[0].mask) == (
        uapi.ATTR_ID_FLAGS,
        uapi.FLAG_OUTPUT,
        0b011,
    )
    assert attrs[1].attr.value.flags == uapi.FLAG_INPUT | uapi.FLAG_ACTIVE_LOW | uapi.FLAG_BIAS_PULL_UP
    assert attrs[1].mask == 0b100
    assert (attrs[2].attr.id, attrs[2].attr.value.values, attrs[2].mask) == (
        uapi.ATTR_ID_OUTPUT_VALUES,
        0b010,
        0b011,
    )
    # Raw bytes at the kernel's offsets: line 0's offset, then the first attribute's id.
    assert int.from_bytes(raw[0:4], "little") == 12
    first_attr = uapi.LineRequest.config.offset + uapi.LineConfig.attrs.offset
    assert int.from_bytes(raw[first_attr : first_attr + 4], "little") == uapi.ATTR_ID_FLAGS


def test_flags_per_line() -> None:
    assert line_flags(LineSpec("o", 1, "output", active_low=True)) == uapi.FLAG_OUTPUT | uapi.FLAG_ACTIVE_LOW
    assert (
        line_flags(LineSpec("i", 1, "input", bias="pull_down")) == uapi.FLAG_INPUT | uapi.FLAG_BIAS_PULL_DOWN
    )


def test_bad_requests_are_refused() -> None:
    with pytest.raises(ValueError):
        uapi.build_request("x", [], [], {})
    with pytest.raises(ValueError):
        uapi.build_request("x", [1, 2], [uapi.FLAG_INPUT], {})


def test_missing_chip_is_a_clear_os_error(tmp_path) -> None:
    from tlt_drivers.gpio.chardev import CharDevLines

    with pytest.raises(FileNotFoundError):
        CharDevLines(str(tmp_path / "gpiochip9"), "tlt", (LineSpec("s", 1, "input"),))
