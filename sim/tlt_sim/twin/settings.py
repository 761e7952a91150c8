"""How the twin process runs (``config/twin/run.yaml``): time, emulator addresses, cameras, viewer.

:func:`load_settings` validates the file with ``tlt_common.config_schema``; a bad value raises
``ConfigError`` naming the file, the key and the reason. Command-line options of
``tlt twin run`` override single values afterwards (:meth:`TwinSettings.replace`).
"""

from __future__ import annotations

import dataclasses
import ipaddress
from dataclasses import dataclass
from pathlib import Path

from tlt_common.config_schema import Field, load_validated, opt

REPO = Path(__file__).resolve().parents[3]
DEFAULT_SETTINGS = REPO / "config" / "twin" / "run.yaml"


def _loopback(value: str) -> str | None:
    try:
        if ipaddress.ip_address(value).is_loopback:
            return None
    except ValueError:
        pass
    return f"expected a loopback address such as 127.0.0.2, got {value!r}"


_SIZE = {"width": Field("int", minimum=16, maximum=1920), "height": Field("int", minimum=16, maximum=1080)}
SCHEMA = {
    "sync_period_s": Field("float", minimum=0.001, maximum=0.05, doc="sim seconds per emulator exchange"),
    "rtf": opt("float", 1.0, minimum=0.0, maximum=1000.0, doc="real-time factor; 0 = as fast as possible"),
    "driver_wait_s": opt("float", 0.5, minimum=0.0, maximum=5.0, doc="wall s to wait for a late driver"),
    "driver_lead_s": opt(
        "float",
        0.05,
        minimum=0.0,
        maximum=1.0,
        doc="sim s a serial driver may lag before the twin waits for it",
    ),
    "ur_hosts": Field(
        "dict",
        schema={"ur_x": Field("str", check=_loopback), "ur_y": Field("str", check=_loopback)},
    ),
    "cameras": Field(
        "dict",
        schema={
            "rate_hz": Field("float", minimum=0.1, maximum=60.0),
            "zed": Field("dict", schema=_SIZE),
            "d405": Field("dict", schema=_SIZE),
            "antialias": opt("bool", True, doc="multisampled frames, as the vision's detectors learned on"),
        },
    ),
    "ground_truth_rate_hz": opt("float", 10.0, minimum=0.1, maximum=500.0),
    "tf_rate_hz": opt("float", 10.0, minimum=0.1, maximum=500.0, doc="/tf messages per simulated second"),
    "viewer": opt(
        "dict",
        {"enabled": False, "rate_hz": 30.0},
        schema={
            "enabled": opt("bool", False, doc="open MuJoCo's viewer window (needs a display)"),
            "rate_hz": opt("float", 30.0, minimum=1.0, maximum=120.0, doc="window updates per wall second"),
        },
    ),
}


@dataclass(frozen=True)
class TwinSettings:
    """Validated run settings; sizes are (width, height) in pixels."""

    sync_period_s: float = 0.02
    rtf: float = 1.0
    driver_wait_s: float = 0.5
    driver_lead_s: float = 0.05
    ur_hosts: dict[str, str] = dataclasses.field(
        default_factory=lambda: {"ur_x": "127.0.0.2", "ur_y": "127.0.0.3"}
    )
    camera_rate_hz: float = 10.0
    zed_size: tuple[int, int] = (640, 480)
    d405_size: tuple[int, int] = (320, 240)
    camera_antialias: bool = True
    ground_truth_rate_hz: float = 10.0
    tf_rate_hz: float = 10.0
    viewer: bool = False
    viewer_rate_hz: float = 30.0

    def replace(self, **changes: object) -> TwinSettings:
        return dataclasses.replace(self, **changes)

    def camera_size(self, camera: str) -> tuple[int, int]:
        return self.d405_size if "d405" in camera else self.zed_size


def load_settings(path: str | Path = DEFAULT_SETTINGS) -> TwinSettings:
    """Read and validate ``run.yaml``."""
    doc = load_validated(path, SCHEMA)
    cams = doc["cameras"]
    return TwinSettings(
        sync_period_s=doc["sync_period_s"],
        rtf=doc["rtf"],
        driver_wait_s=doc["driver_wait_s"],
        driver_lead_s=doc["driver_lead_s"],
        ur_hosts=dict(doc["ur_hosts"]),
        camera_rate_hz=cams["rate_hz"],
        zed_size=(cams["zed"]["width"], cams["zed"]["height"]),
        d405_size=(cams["d405"]["width"], cams["d405"]["height"]),
        camera_antialias=cams["antialias"],
        ground_truth_rate_hz=doc["ground_truth_rate_hz"],
        tf_rate_hz=doc["tf_rate_hz"],
        viewer=doc["viewer"]["enabled"],
        viewer_rate_hz=doc["viewer"]["rate_hz"],
    )


__all__ = ["DEFAULT_SETTINGS", "SCHEMA", "TwinSettings", "load_settings"]
