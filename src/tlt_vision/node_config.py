"""The vision node's configuration: ``config/vision/node.yaml``, validated on load.

Reads the YAML file (with ``tlt_common.config_schema``) and checks what the schema cannot: every
alias names a configured camera, every EE camera's arm has a base, the bay cameras exist, the depth
range is ordered, and the segmentation source is known. Paths are resolved against the repository
root. Any problem raises :class:`~tlt_common.config_schema.ConfigError` naming the file, the key and
the reason; nothing is returned half-checked.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from tlt_common.config_schema import ConfigError, Field, load_yaml, opt, validate
from tlt_common.geometry.transforms import pose_matrix, rpy_matrix
from tlt_common.mission.tag_mounts import TAG_MOUNT_SCHEMA
from tlt_vision.depth_noise import EXACT, DepthNoise
from tlt_vision.pointcloud import DEFAULT_DETACHED as DETACHED
from tlt_vision.pointcloud import Detached
from tlt_vision.pose.axial_slide import DEFAULT as AXIAL_SLIDE
from tlt_vision.pose.axial_slide import AxialSlide
from tlt_vision.pose.free_space import DEFAULT as FREE_SPACE
from tlt_vision.pose.free_space import FreeSpace
from tlt_vision.pose.parting import DEFAULT as PARTING
from tlt_vision.pose.parting import Parting
from tlt_vision.segmentation.config import CLASSES
from tlt_vision.segmentation.depth_split import DepthSplit
from tlt_vision.segmentation.overlap import ExclusiveOverlaps
from tlt_vision.segmentation.semantic_trim import SemanticTrim

# Parts about as long as they are wide, seen whole or hardly at all.
COMPACT = ("end_fitting", "corner_joint", "rivet")

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_CONFIG = REPO_ROOT / "config" / "vision" / "node.yaml"
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
                doc="the most allowed for noise, a fraction of the part's size",
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


def pose_of(entry: dict[str, Any]) -> np.ndarray:
    """4x4 pose of a ``{position, rpy}`` entry (rpy as URDF: R = Rz(yaw) Ry(pitch) Rx(roll))."""
    return pose_matrix(entry["position"], rpy_matrix(entry["rpy"]))


def repo_path(path: str) -> Path:
    p = Path(path)
    return p if p.is_absolute() else REPO_ROOT / p


@dataclass(frozen=True)
class VisionConfig:
    """The validated file; ``raw`` holds every key with defaults filled in."""

    raw: dict[str, Any]
    source: str

    @property
    def cameras(self) -> list[str]:
        return [*self.raw["lifter_cameras"], *self.raw["ee_cameras"]]

    def resolve_camera(self, name: str) -> str | None:
        """The configured camera ``name`` means (directly or through an alias), or None."""
        name = self.raw["camera_aliases"].get(name, name)
        return name if name in self.cameras else None

    @property
    def depth_noise(self) -> DepthNoise:
        """The noise of the cameras ``depth_noise.cameras`` does not name."""
        raw = self.raw["depth_noise"]
        return DepthNoise(raw["fraction"], raw["window"], raw["max_allowance"])

    def with_exact_depth(self) -> VisionConfig:
        """This configuration with every camera's depth taken as exact: for the twin's exact
        cameras (``tlt twin run --camera-model exact``), a diagnosis."""
        raw = copy.deepcopy(self.raw)
        raw["depth_noise"].update(fraction=0.0, cameras={})
        return VisionConfig(raw, self.source)

    def depth_noise_of(self, camera: str, fx: float | None = None) -> DepthNoise:
        """The noise of the configured ``camera``'s depth; given the frame's focal length ``fx``
        (pixels), with the share of it that neighbouring pixels' sharing leaves after the filter."""
        default = self.depth_noise
        own = self.raw["depth_noise"]["cameras"].get(camera)
        if own is None:
            return default
        if not isinstance(own, dict):
            return replace(default, fraction=own)
        noise = replace(
            default,
            **{k: float(own.get(k, 0.0)) for k in ("fraction", "per_m2", "correlation_px", "focal_px")},
        )
        return noise if fx is None else noise.for_frame(fx)

    @property
    def free_space(self) -> FreeSpace:
        return FreeSpace(**self.raw["free_space"])

    @property
    def axial_slide(self) -> AxialSlide | None:
        raw = self.raw["axial_slide"]
        return AxialSlide(**{**raw, "classes": tuple(raw["classes"])}) if raw["classes"] else None

    @property
    def pipeline_options(self) -> dict[str, Any]:
        """The keyword arguments of :class:`tlt_vision.pipeline.PartPipeline` this file sets."""
        raw = self.raw
        return {
            "max_points": raw["max_points"],
            "keep_border_below": raw["keep_border_below"],
            "free_space": self.free_space,
            "detached": self.detached,
            "axial_slide": self.axial_slide,
            "depth_noise": self.depth_noise,
            "parting": self.parting,
        }

    @property
    def mask_rcnn_inference(self) -> dict[str, Any]:
        """The Mask R-CNN's inference settings node.yaml sets (MaskRCNN.set_inference); the
        weights' own for those left out."""
        seg = self.raw["segmentation"]
        named = {
            "semantic_background_weight": seg["semantic_background_weight"],
            "rpn_post_nms_top_n_test": seg["proposals"],
            "semantic_vote": seg["semantic_vote"],
        }
        return {key: value for key, value in named.items() if value is not None}

    @property
    def score_floor(self) -> float:
        """The lowest score a segmenter keeps: ``second_look_score`` when set, else ``min_score``."""
        seg = self.raw["segmentation"]
        return seg["min_score"] if seg["second_look_score"] is None else seg["second_look_score"]

    @property
    def parting(self) -> Parting:
        """Which refused clouds are posed again on the larger of two pieces (none when its classes
        are empty), and when a second pose is taken (that of a mask's core too)."""
        raw = self.raw["parting"]
        return Parting(**{**raw, "classes": tuple(raw["classes"])})

    @property
    def detached(self) -> Detached:
        """Which pieces of a part's cloud are dropped before its pose."""
        raw = self.raw["detached"]
        return Detached(
            **{
                **raw,
                "largest_only": tuple(raw["largest_only"]),
                "links": tuple(sorted(raw["links"].items())),
            }
        )

    @property
    def depth_split(self) -> DepthSplit | None:
        """How Mask R-CNN's thin-part regions are cut where the depth jumps; None: not cut."""
        raw = self.raw["segmentation"]["depth_split"]
        if not raw:
            return None
        band = raw["width_band"]
        return DepthSplit(
            **{
                **raw,
                "width_band": tuple(band) if band else None,
                "depth_noise": self.depth_noise,
                "vote": self.raw["segmentation"]["semantic_vote"],
            }
        )

    @property
    def semantic_trim(self) -> SemanticTrim | None:
        """Which box-branch masks lose the pixels the semantic head holds to be a thin part."""
        raw = self.raw["segmentation"]["semantic_trim"]
        return SemanticTrim(tuple(raw["classes"]), raw["above"], tuple(raw["cores"])) if raw else None

    @property
    def exclusive_overlaps(self) -> ExclusiveOverlaps | None:
        """Which box-branch classes' masks give the pixels they share to the more probable one."""
        raw = self.raw["segmentation"]["exclusive_overlaps"]
        return ExclusiveOverlaps(tuple(raw["classes"]), raw["duplicate"]) if raw else None

    def detector_path(self, model: str) -> Path:
        return repo_path(self.raw["detectors"][model])

    @property
    def mission_path(self) -> Path:
        return repo_path(self.raw["mission"])


def _check(raw: dict[str, Any], source: str) -> None:
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


def config_from_dict(data: Any, source: str = "<vision config>") -> VisionConfig:
    raw = validate(data, SCHEMA, source=source)
    _check(raw, source)
    return VisionConfig(raw, source)


def load_config(path: str | Path = DEFAULT_CONFIG, mission: str | Path | None = None) -> VisionConfig:
    """Load and check ``path``; ``mission`` replaces the file's mission. Raises ConfigError."""
    cfg = config_from_dict(load_yaml(path), str(path))
    if mission is not None:
        cfg.raw["mission"] = str(mission)
    return cfg


__all__ = [
    "DEFAULT_CONFIG",
    "MODEL_NAMES",
    "SEGMENTATION_SOURCES",
    "VisionConfig",
    "config_from_dict",
    "load_config",
    "pose_of",
    "repo_path",
]
