"""The Linux GPIO character-device uAPI, version 2 (``linux/gpio.h``), as ctypes structures.

Only what a line request needs: ``struct gpio_v2_line_request`` (with its ``gpio_v2_line_config``
and per-line attributes), ``struct gpio_v2_line_values``, ``struct gpiochip_info`` and the ioctl
numbers built the way the kernel's ``_IOR``/``_IOWR`` macros build them. The layouts follow the
kernel header field by field, including its explicit padding, so ``ctypes.sizeof`` matches the
C ``sizeof`` on 64-bit Linux (the Jetsons' aarch64 and x86-64 alike).
"""

from __future__ import annotations

import ctypes

LINES_MAX = 64
NUM_ATTRS_MAX = 10
MAX_NAME_SIZE = 32

FLAG_USED = 1 << 0
FLAG_ACTIVE_LOW = 1 << 1
FLAG_INPUT = 1 << 2
FLAG_OUTPUT = 1 << 3
FLAG_EDGE_RISING = 1 << 4
FLAG_EDGE_FALLING = 1 << 5
FLAG_OPEN_DRAIN = 1 << 6
FLAG_OPEN_SOURCE = 1 << 7
FLAG_BIAS_PULL_UP = 1 << 8
FLAG_BIAS_PULL_DOWN = 1 << 9
FLAG_BIAS_DISABLED = 1 << 10

ATTR_ID_FLAGS = 1
ATTR_ID_OUTPUT_VALUES = 2
ATTR_ID_DEBOUNCE = 3


class _AttrValue(ctypes.Union):
    _fields_ = (
        ("flags", ctypes.c_uint64),
        ("values", ctypes.c_uint64),
        ("debounce_period_us", ctypes.c_uint32),
    )


class LineAttribute(ctypes.Structure):
    _fields_ = (("id", ctypes.c_uint32), ("padding", ctypes.c_uint32), ("value", _AttrValue))


class LineConfigAttribute(ctypes.Structure):
    _fields_ = (("attr", LineAttribute), ("mask", ctypes.c_uint64))


class LineConfig(ctypes.Structure):
    _fields_ = (
        ("flags", ctypes.c_uint64),
        ("num_attrs", ctypes.c_uint32),
        ("padding", ctypes.c_uint32 * 5),
        ("attrs", LineConfigAttribute * NUM_ATTRS_MAX),
    )


class LineRequest(ctypes.Structure):
    _fields_ = (
        ("offsets", ctypes.c_uint32 * LINES_MAX),
        ("consumer", ctypes.c_char * MAX_NAME_SIZE),
        ("config", LineConfig),
        ("num_lines", ctypes.c_uint32),
        ("event_buffer_size", ctypes.c_uint32),
        ("padding", ctypes.c_uint32 * 5),
        ("fd", ctypes.c_int32),
    )


class LineValues(ctypes.Structure):
    _fields_ = (("bits", ctypes.c_uint64), ("mask", ctypes.c_uint64))


class ChipInfo(ctypes.Structure):
    _fields_ = (
        ("name", ctypes.c_char * MAX_NAME_SIZE),
        ("label", ctypes.c_char * MAX_NAME_SIZE),
        ("lines", ctypes.c_uint32),
    )


# asm-generic/ioctl.h: direction in bits 30-31, size in 16-29, type in 8-15, number in 0-7.
_IOC_WRITE = 1
_IOC_READ = 2


def _ioc(direction: int, kind: int, number: int, size: int) -> int:
    return (direction << 30) | (size << 16) | (kind << 8) | number


GPIO_GET_CHIPINFO_IOCTL = _ioc(_IOC_READ, 0xB4, 0x01, ctypes.sizeof(ChipInfo))
GPIO_V2_GET_LINE_IOCTL = _ioc(_IOC_READ | _IOC_WRITE, 0xB4, 0x07, ctypes.sizeof(LineRequest))
GPIO_V2_LINE_SET_CONFIG_IOCTL = _ioc(_IOC_READ | _IOC_WRITE, 0xB4, 0x0D, ctypes.sizeof(LineConfig))
GPIO_V2_LINE_GET_VALUES_IOCTL = _ioc(_IOC_READ | _IOC_WRITE, 0xB4, 0x0E, ctypes.sizeof(LineValues))
GPIO_V2_LINE_SET_VALUES_IOCTL = _ioc(_IOC_READ | _IOC_WRITE, 0xB4, 0x0F, ctypes.sizeof(LineValues))


def build_request(
    consumer: str, offsets: list[int], line_flags: list[int], output_values: dict[int, bool]
) -> LineRequest:
    """A line request for ``offsets`` (chip line numbers), each with its own flags.

    Lines sharing the same flags share one FLAGS attribute (bit i of an attribute's mask is
    ``offsets[i]``); ``output_values`` (index into ``offsets`` -> level) becomes one
    OUTPUT_VALUES attribute so outputs start at a defined level.
    """
    if not 0 < len(offsets) <= LINES_MAX:
        raise ValueError(f"a request holds 1..{LINES_MAX} lines, got {len(offsets)}")
    if len(line_flags) != len(offsets):
        raise ValueError("one flags value per line is needed")
    groups: dict[int, int] = {}
    for index, flags in enumerate(line_flags):
        groups[flags] = groups.get(flags, 0) | (1 << index)
    if len(groups) + (1 if output_values else 0) > NUM_ATTRS_MAX:
        raise ValueError(f"more than {NUM_ATTRS_MAX} distinct line configurations")
    req = LineRequest()
    for index, offset in enumerate(offsets):
        req.offsets[index] = offset
    req.consumer = consumer.encode("ascii", errors="replace")[: MAX_NAME_SIZE - 1]
    req.num_lines = len(offsets)
    attrs = []
    for flags, mask in groups.items():
        attr = LineConfigAttribute(mask=mask)
        attr.attr.id = ATTR_ID_FLAGS
        attr.attr.value.flags = flags
        attrs.append(attr)
    if output_values:
        attr = LineConfigAttribute()
        attr.attr.id = ATTR_ID_OUTPUT_VALUES
        for index, level in output_values.items():
            attr.mask |= 1 << index
            if level:
                attr.attr.value.values |= 1 << index
        attrs.append(attr)
    req.config.num_attrs = len(attrs)
    for i, attr in enumerate(attrs):
        req.config.attrs[i] = attr
    return req
