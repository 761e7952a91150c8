"""The schema of the vision node's configuration (``config/vision/node.yaml``) and the checks
across its keys that a schema cannot state: every alias names a configured camera, every EE camera's
arm has a base, the bay cameras exist, the depth range is ordered, and the segmentation source is
known. :mod:`tlt_vision.node_config` loads a file against them.
"""

from __future__ import annotations

from typing import Any

from tlt_common.config_schema import ConfigError, Field, opt
from tlt_common.mission.tag_mounts import TAG_MOUNT_SCHEMA
from tlt_vision.depth_noise import EXACT
from tlt_vision.pointcloud import DEFAULT_DETACHED as DETACHED
from tlt_vision.pose.axial_ends import DEFAULT as AXIAL_ENDS
from tlt_vision.pose.axial_slide import DEFAULT as AXIAL_SLIDE
from tlt_vision.pose.free_space import DEFAULT as FREE_SPACE
from tlt_vision.pose.parting import DEFAULT as PARTING
from tlt_vision.segmentation.config import CLASSES

# Parts about as long as they are wide, seen whole or hardly at all.
COMPACT = ("end_fitting", "corner_joint", "rivet")

SEGMENTATION_SOURCES = ("twin_labels", "mask_rcnn")
MODEL_NAMES = (
    "strut_tube/vertical",
    "strut_tube/diagonal",
    "end_fitting",
    "cross_frame",
    "corner_joint",
    "rivet",
)


def _vec(n: int) -> Field:
    return Field(
        "list", item=Field("float"), check=lambda v: None if len(v) == n else f"expected {n} numbers"
    )


def _band(v: list[float]) -> str | None:
    return None if len(v) == 2 and v[0] < v[1] else "expected [low, high] with low < high"


_POSE = Field("dict", schema={"position": _vec(3), "rpy": _vec(3)})
_POSITIVE = {"minimum": 1e-6}


def _camera_noise(value: object) -> str | None:
    """A camera's depth noise: a fraction of the depth, or {fraction, per_m2, correlation_px,
    focal_px}."""

    def bad(v: object, top: float) -> bool:
        return isinstance(v, bool) or not isinstance(v, int | float) or not 0.0 <= v <= top

    if isinstance(value, dict):
        tops = {"fraction": 0.1, "per_m2": 0.1, "correlation_px": 20.0, "focal_px": 10000.0}
        unknown = set(value) - set(tops)
        if unknown:
            return f"unknown keys {sorted(unknown)} ({', '.join(tops)})"
        for key, top in tops.items():
            if bad(value.get(key, 0.0), top):
                return f"{key} must be a number from 0 to {top:g}, got {value.get(key)!r}"
        return None
    if bad(value, 0.1):
        return f"expected a fraction of the depth from 0 to 0.1 or {{fraction, per_m2, ...}}, got {value!r}"
    return None


SCHEMA = {
    "format": Field("int", choices=(1,)),
    "mission": Field("str"),
    "world_frame": opt("str", "world"),
    "segmentation": Field(
        "dict",
        schema={
            "source": Field("str", choices=SEGMENTATION_SOURCES),
            "weights": opt("str", ""),
            "min_score": opt("float", 0.5, minimum=0.0, maximum=1.0),
            "second_look_score": opt("float", None, minimum=0.0, maximum=1.0),
            "semantic_background_weight": opt("float", None, minimum=0.01, maximum=1.0),
            "semantic_vote": opt(
                "bool", False, doc="a thin region or piece of the class with the most probability over it"
            ),
            "proposals": opt(
                "int", None, minimum=1, maximum=5000, doc="region proposals per image the box branch scores"
            ),
            "second_look_closer": opt(
                "dict",
                None,
                schema={
                    "size": Field("float", minimum=0.01, maximum=2.0, doc="region edge at the place, m"),
                    "scale": Field("float", minimum=1.0, maximum=8.0, doc="how much it is enlarged"),
                },
            ),
            "depth_split": opt(
                "dict",
                None,
                schema={
                    "jump": Field("float", minimum=0.0, doc="depth step that cuts a region, m"),
                    "jump_per_m": Field("float", minimum=0.0, doc="and more per metre of depth"),
                    "min_area": Field("int", minimum=1, doc="smallest piece kept, pixels"),
                    "full_score_area": Field("int", minimum=1, doc="pieces smaller scored less, pixels"),
                    "join_angle_deg": opt("float", 5.0, minimum=0.0, maximum=90.0),
                    "join_offset": opt("float", 0.015, minimum=0.0),
                    "join_gap": opt("float", 0.3, minimum=0.0),
                    "width_band": opt(
                        "list",
                        None,
                        item=Field("float", minimum=0.0),
                        check=_band,
                        doc="a piece's mean image width over its part's, outside which it is scored down",
                    ),
                    "width_penalty": opt("float", 0.3, minimum=0.0, maximum=1.0),
                    "bend_tolerance": opt(
                        "float",
                        None,
                        minimum=0.5,
                        doc="a bent piece is cut into straight ones, points within this many radii of each",
                    ),
                },
            ),
            "semantic_trim": opt(
                "dict",
                None,
                schema={
                    "classes": Field("list", item=Field("str", choices=CLASSES), doc="masks trimmed"),
                    "above": Field("float", minimum=0.0, maximum=1.0, doc="a thin part's probability"),
                    "cores": opt(
                        "list",
                        [],
                        item=Field("str", choices=CLASSES),
                        doc="masks kept whole, their trimmed masks fitted where theirs is refused",
                    ),
                },
            ),
            "exclusive_overlaps": opt(
                "dict",
                None,
                schema={
                    "classes": Field("list", item=Field("str", choices=CLASSES), doc="masks made exclusive"),
                    "duplicate": Field(
                        "float",
                        minimum=0.0,
                        maximum=1.0,
                        doc="share of the smaller mask above which two are one part's",
                    ),
                },
            ),
        },
    ),
    "detectors": Field("dict", schema={name: Field("str", doc="weights file (.pt)") for name in MODEL_NAMES}),
    "max_points": opt("int", 1024, minimum=32),
    "keep_border_below": opt("int", 0, minimum=0),
    "torch_threads": opt("int", 1, minimum=1),
    "corrector": Field(
        "dict",
        schema={
            "max_iterations": Field("int", minimum=1, maximum=2000),
            "step": Field("float", **_POSITIVE),
            "decay": Field("float", minimum=0.5, maximum=1.0),
            "patience": Field("int", minimum=1),
            "tolerance": opt("float", 1e-4, minimum=0.0, maximum=1.0),
            "refine_iterations": opt("int", 0, minimum=0, maximum=500),
            "points": opt("int", 0, minimum=0),
            # Parts round about their model's z axis and about as long as wide.
            "turned_starts": opt("list", [], item=Field("str", choices=("end_fitting", "rivet"))),
            "tilted_starts": opt(
                "dict",
                {"classes": [], "angle_deg": 30.0},
                schema={
                    "classes": opt("list", [], item=Field("str", choices=COMPACT)),
                    "angle_deg": opt("float", 30.0, minimum=1.0, maximum=90.0),
                },
            ),
            "trim": opt(
                "dict",
                {"classes": [], "fraction": 0.1},
                schema={
                    "classes": opt("list", [], item=Field("str", choices=CLASSES)),
                    "fraction": opt("float", 0.1, minimum=0.0, maximum=0.5),
                },
            ),
        },
    ),
    "depth_noise": opt(
        "dict",
        {
            "fraction": EXACT.fraction,
            "window": EXACT.window,
            "max_allowance": EXACT.max_allowance,
            "precision_sigmas": EXACT.precision_sigmas,
            "cameras": {},
        },
        schema={
            "fraction": opt(
                "float",
                EXACT.fraction,
                minimum=0.0,
                maximum=0.1,
                doc="the depth cameras' noise, 1 sigma, a fraction of the depth",
            ),
            "window": opt(
                "int",
                EXACT.window,
                minimum=1,
                maximum=15,
                check=lambda v: None if v % 2 else "must be odd",
                doc="pixels of the square whose median depth a point takes",
            ),
            "max_allowance": opt(
                "float",
                EXACT.max_allowance,
                minimum=0.0,
                maximum=0.5,
                doc="the most a certified pose may be off (ADD-S), a fraction of the part's size",
            ),
            "precision_sigmas": opt(
                "float",
                EXACT.precision_sigmas,
                minimum=0.5,
                maximum=6.0,
                doc="the standard errors of a fitted pose's ADD-S that must lie within max_allowance",
            ),
            # A ZED's noise is not a D405's: a camera named here has its own, a fraction of the
            # depth or {fraction, per_m2} (a stereo camera's, growing with the depth's square).
            "cameras": opt(
                "map", {}, item=Field("any", check=_camera_noise), doc="a configured camera's own noise"
            ),
        },
    ),
    "free_space": opt(
        "dict",
        {"margin": FREE_SPACE.margin, "max_fraction": FREE_SPACE.max_fraction, "window": FREE_SPACE.window},
        schema={
            "margin": opt("float", FREE_SPACE.margin, minimum=0.0, maximum=0.1),
            "max_fraction": opt("float", FREE_SPACE.max_fraction, minimum=0.0, maximum=1.0),
            "window": opt(
                "int",
                FREE_SPACE.window,
                minimum=1,
                maximum=31,
                check=lambda v: None if v % 2 else "must be odd",
            ),
        },
    ),
    "axial_slide": opt(
        "dict",
        {
            "classes": [],
            "step": AXIAL_SLIDE.step,
            "hidden_margin": AXIAL_SLIDE.hidden_margin,
            "min_gain": AXIAL_SLIDE.min_gain,
        },
        schema={
            # Parts round about their model's z axis.
            "classes": opt("list", [], item=Field("str", choices=("end_fitting", "strut_tube", "rivet"))),
            "step": opt("float", AXIAL_SLIDE.step, minimum=0.0001, maximum=0.01),
            "hidden_margin": opt("float", AXIAL_SLIDE.hidden_margin, minimum=0.0, maximum=0.05),
            "min_gain": opt("float", AXIAL_SLIDE.min_gain, minimum=0.0, maximum=1.0),
        },
    ),
    "axial_ends": opt(
        "dict",
        {
            "classes": [],
            "offsets_px": list(AXIAL_ENDS.offsets_px),
            "on_surface": AXIAL_ENDS.on_surface,
            "jump": AXIAL_ENDS.jump,
        },
        schema={
            # Cylinders whose model lies along its z axis, with dims radius and half_length.
            "classes": opt("list", [], item=Field("str", choices=("end_fitting", "rivet"))),
            "offsets_px": opt(
                "list",
                list(AXIAL_ENDS.offsets_px),
                item=Field("float", minimum=1.0, maximum=30.0),
                min_items=1,
            ),
            "on_surface": opt("float", AXIAL_ENDS.on_surface, minimum=0.0, maximum=0.05),
            "jump": opt("float", AXIAL_ENDS.jump, minimum=0.0, maximum=0.05),
        },
    ),
    "parting": opt(
        "dict",
        {
            "classes": [],
            "min_share": PARTING.min_share,
            "min_separation": PARTING.min_separation,
            "in_mask": PARTING.in_mask,
            "mask_margin": PARTING.mask_margin,
            "hidden_margin": PARTING.hidden_margin,
        },
        schema={
            # Compact parts only: a tube or a frame side is long, and its two halves are one part.
            "classes": opt("list", [], item=Field("str", choices=COMPACT)),
            "min_share": opt(
                "float",
                PARTING.min_share,
                minimum=0.0,
                maximum=0.5,
                doc="the smaller piece's least share of the cloud's points",
            ),
            "min_separation": opt(
                "float",
                PARTING.min_separation,
                minimum=0.0,
                maximum=2.0,
                doc="the pieces' centres' least distance, a fraction of the part's size",
            ),
            "in_mask": opt(
                "float",
                PARTING.in_mask,
                minimum=0.0,
                maximum=1.0,
                doc="the least share of the posed model's visible surface in the mask",
            ),
            "mask_margin": opt(
                "int",
                PARTING.mask_margin,
                minimum=0,
                maximum=10,
                doc="pixels the mask is grown by for that share",
            ),
            "hidden_margin": opt(
                "float",
                PARTING.hidden_margin,
                minimum=0.0,
                maximum=0.1,
                doc="m behind the depth seen at which a model point is hidden",
            ),
        },
    ),
    "detached": opt(
        "dict",
        {"link": DETACHED.link, "below": DETACHED.below, "largest_only": [], "links": {}},
        schema={
            "link": opt("float", DETACHED.link, minimum=0.001, maximum=0.5),
            "below": opt("float", DETACHED.below, minimum=0.0, maximum=0.5),
            # Compact parts only: a tube or a frame side cut by what stands in front is two pieces.
            "largest_only": opt("list", [], item=Field("str", choices=COMPACT)),
            # A compact part's own link: its points lie closer together than a tube's, and so do
            # its neighbours.
            "links": opt(
                "map",
                {},
                item=Field("float", minimum=0.001, maximum=0.5),
                check=lambda v: (
                    None
                    if set(v) <= set(COMPACT)
                    else f"keys are compact part classes ({', '.join(COMPACT)})"
                ),
            ),
        },
    ),
    "ee_self_filter": opt(
        "dict",
        {"margin": 0.01, "boxes": {}, "own_share": 0.9},
        schema={
            "margin": opt("float", 0.01, minimum=0.0, maximum=0.1),
            # Under a half, a part's mask that took in a gun beside it would be set aside as the gun.
            "own_share": opt("float", 0.9, minimum=0.5, maximum=1.0),
            "boxes": opt(
                "map",
                {},
                item=Field(
                    "dict",
                    schema={"centre": _vec(3), "half": _vec(3), "on_width_slide": Field("bool")},
                ),
            ),
            "jaws": opt(
                "map",
                {},
                check=lambda v: None if set(v) <= {"a", "b"} else "keys are the grasp sides a and b",
                item=Field(
                    "dict",
                    schema={
                        "hinge": _vec(3),
                        "tip": _vec(3),
                        "radius": Field("float", **_POSITIVE),
                        "on_width_slide": Field("bool"),
                    },
                ),
            ),
        },
    ),
    "timeouts": Field(
        "dict",
        schema={
            "frame_s": Field("float", **_POSITIVE),
            "request_s": Field("float", **_POSITIVE),
            "joint_state_age_s": Field("float", **_POSITIVE),
        },
    ),
    "topics": Field(
        "dict",
        schema={
            "image": Field(
                "str",
                check=lambda v: (
                    None if "{camera}" in v and "{stream}" in v else "must contain {camera} and {stream}"
                ),
            ),
            "segmentation_labels": Field("str"),
        },
    ),
    "camera_aliases": opt("map", {}, item=Field("str")),
    "part_depth_range": _vec(2),
    "min_part_area": Field("float", minimum=0.0, maximum=1.0),
    "part_gap": opt("float", 0.03, minimum=0.001),
    "held_piece_gate": opt("float", 0.1, minimum=0.001),
    "bay_min_corner_joints": opt("int", 4, minimum=3),
    "lifter_cameras": Field(
        "map", item=Field("dict", schema={"joint": Field("str"), "hinge": _POSE, "optical": _POSE})
    ),
    "arms": Field("map", item=Field("dict", schema={"base": _POSE})),
    "ee_cameras": Field(
        "map",
        item=Field(
            "dict",
            schema={
                "arm": Field("str"),
                "on_width_slide": Field("bool"),
                "optical": _POSE,
                "rivet_gun": Field("dict", schema={"name": Field("str"), "position": _vec(3)}),
            },
        ),
    ),
    "tool": _POSE,
    "site": Field("dict", schema={"base_origin": _vec(3), "build_level": Field("float")}),
    "rivet_in_gun_radius": Field("float", **_POSITIVE),
    "bay_cameras": Field("list", item=Field("str"), min_items=1),
    "tag_mount": Field("dict", schema=TAG_MOUNT_SCHEMA),
}


def check_across_keys(raw: dict[str, Any], source: str) -> None:
    cameras = set(raw["lifter_cameras"]) | set(raw["ee_cameras"])
    for alias, target in raw["camera_aliases"].items():
        if target not in cameras:
            raise ConfigError(source, f"camera_aliases.{alias}", f"names unknown camera {target!r}")
    for name, cam in raw["ee_cameras"].items():
        if cam["arm"] not in raw["arms"]:
            raise ConfigError(source, f"ee_cameras.{name}.arm", f"no base for arm {cam['arm']!r} under arms")
    for i, name in enumerate(raw["bay_cameras"]):
        if name not in raw["lifter_cameras"]:
            raise ConfigError(source, f"bay_cameras[{i}]", f"{name!r} is not a lifter camera")
    for name in raw["depth_noise"]["cameras"]:
        if name not in cameras:
            raise ConfigError(source, f"depth_noise.cameras.{name}", f"names unknown camera {name!r}")
    near, far = raw["part_depth_range"]
    if not 0 <= near < far:
        raise ConfigError(source, "part_depth_range", f"expected 0 <= near < far, got [{near}, {far}]")
    if raw["segmentation"]["source"] == "mask_rcnn" and not raw["segmentation"]["weights"]:
        raise ConfigError(source, "segmentation.weights", "mask_rcnn needs a weights file")
    low, least = raw["segmentation"]["second_look_score"], raw["segmentation"]["min_score"]
    if low is not None and low > least:
        raise ConfigError(source, "segmentation.second_look_score", f"{low} is above min_score {least}")
