"""The part classes' CAD models, built from the part dimensions and the mission geometry.

Reads ``config/vision/parts.yaml`` (part radii and lengths) and ``config/vision/keypoints.yaml``
(keypoints, groups and visibility rules), and a mission's geometry (bay width, strut lengths).
:func:`build_models` returns one :class:`CadModel` per model name: ``strut_tube/vertical``,
``strut_tube/diagonal``, ``end_fitting``, ``cross_frame``, ``corner_joint`` and ``rivet``. The
geometry is the twin's (sim/tlt_sim/model/generate/parts.py): a strut of length L has its fittings
between ``corner_size/2`` and ``corner_size/2 + fitting_length`` from each end and its tube (a
capsule) between them; a cross frame's sides are capsules between corner cubes.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from tlt_common.config_schema import ConfigError, Field, load_validated, opt
from tlt_vision.cad.primitives import Box, Primitive, Segment, sample_surface
from tlt_vision.cad.surface import SurfaceDistance

CLASSES = ("strut_tube", "end_fitting", "cross_frame", "corner_joint", "rivet")
CONFIG_DIR = Path(__file__).resolve().parents[3] / "config" / "vision"
PARTS_FILE = CONFIG_DIR / "parts.yaml"
KEYPOINTS_FILE = CONFIG_DIR / "keypoints.yaml"

_POSITIVE = {"minimum": 1e-6}
PARTS_SCHEMA = {
    "format": Field("int", choices=(1,)),
    "tube_radius": Field("float", **_POSITIVE),
    "cross_frame_tube_radius": Field("float", **_POSITIVE),
    "fitting_radius": Field("float", **_POSITIVE),
    "fitting_length": Field("float", **_POSITIVE),
    "corner_size": Field("float", **_POSITIVE),
    "rivet_radius": Field("float", **_POSITIVE),
    "rivet_length": Field("float", **_POSITIVE),
    "sample_density": opt("float", 400000.0, minimum=1.0, doc="points per m^2"),
    "min_samples": opt("int", 256, minimum=8),
    "max_samples": opt("int", 2048, minimum=8),
}

_VEC3 = Field("list", item=Field("float"), check=lambda v: None if len(v) == 3 else "expected 3 numbers")
_SCALE_NAMES = ("radius", "half_length", "half_width", "half_size")
CLASS_SCHEMA = {
    "scale": Field(
        "list",
        item=Field("str", choices=_SCALE_NAMES),
        check=lambda v: None if len(v) == 3 else "expected 3 names",
    ),
    "keypoints": Field("map", item=_VEC3, check=lambda v: None if v else "needs at least one keypoint"),
    "groups": Field("map", item=Field("list", item=Field("str"), min_items=1)),
    "group_min_visible": Field("int", minimum=1),
    "groups_required": Field("int", minimum=1),
    "visibility_radius": Field("float", minimum=1e-6, doc="m"),
    "min_points": Field("int", minimum=1),
}
KEYPOINTS_SCHEMA = {
    "format": Field("int", choices=(1,)),
    "classes": Field("dict", schema={c: Field("dict", schema=CLASS_SCHEMA) for c in CLASSES}),
}


@dataclass(frozen=True)
class Visibility:
    """The non-degeneracy rule of a class (see config/vision/keypoints.yaml)."""

    groups: dict[str, tuple[int, ...]]
    group_min_visible: int
    groups_required: int
    radius: float
    min_points: int


@dataclass(frozen=True)
class CadModel:
    """One part model: surface primitives, keypoints (K, 3) in its frame, and its symmetries.

    ``symmetries`` (P, K) lists keypoint permutations under the model's proper rotational
    symmetries (identity first): a pose and its symmetric images fit the model equally well, so
    keypoint losses take the minimum over them.
    """

    name: str
    object_class: str
    dims: dict[str, float]
    primitives: tuple[Primitive, ...]
    keypoint_names: tuple[str, ...]
    keypoints: np.ndarray
    visibility: Visibility
    symmetries: np.ndarray
    sample_density: float = 400000.0
    min_samples: int = 256
    max_samples: int = 2048
    symmetry_rotations: np.ndarray = field(default_factory=lambda: np.eye(3)[None])

    @cached_property
    def surface(self) -> SurfaceDistance:
        """Exact point-to-surface distance of this model (model frame)."""
        return SurfaceDistance(self.primitives)

    @property
    def area(self) -> float:
        return float(sum(p.area() for p in self.primitives))

    @cached_property
    def diameter(self) -> float:
        """Bounding-box diagonal of a surface sample, m (the part's size for relative errors)."""
        pts, _ = self.sample(512, np.random.default_rng(0))
        return float(np.linalg.norm(pts.max(0) - pts.min(0)))

    @property
    def default_samples(self) -> int:
        n = int(self.area * self.sample_density)
        return int(min(max(n, self.min_samples), self.max_samples))

    def sample(
        self, n: int | None = None, rng: np.random.Generator | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``n`` surface points (n, 3) and normals, uniform by area; ``n`` defaults by density."""
        rng = rng if rng is not None else np.random.default_rng(0)
        return sample_surface(self.primitives, n or self.default_samples, rng)


def load_parts(path: str | Path = PARTS_FILE) -> dict[str, Any]:
    """The validated part dimensions; :class:`ConfigError` names file, key and reason."""
    data = load_validated(path, PARTS_SCHEMA)
    if data["min_samples"] > data["max_samples"]:
        raise ConfigError(path, "min_samples", "must not exceed max_samples")
    return data


def thin_part_radii(parts: dict[str, Any] | None = None) -> dict[str, float]:
    """The radius of each thin class Mask R-CNN's semantic head segments (a strut's tube, a cross
    frame's sides), m: what their regions' widths are checked against."""
    parts = parts if parts is not None else load_parts()
    return {"strut_tube": parts["tube_radius"], "cross_frame": parts["cross_frame_tube_radius"]}


def load_keypoints(path: str | Path = KEYPOINTS_FILE) -> dict[str, dict[str, Any]]:
    """The validated keypoint annotations; every group member must name a keypoint of its class."""
    data = load_validated(path, KEYPOINTS_SCHEMA)["classes"]
    for cls, spec in data.items():
        for group, members in spec["groups"].items():
            for m in members:
                if m not in spec["keypoints"]:
                    raise ConfigError(path, f"classes.{cls}.groups.{group}", f"unknown keypoint {m!r}")
            if spec["group_min_visible"] > len(members):
                raise ConfigError(
                    path,
                    f"classes.{cls}.group_min_visible",
                    f"group {group} has only {len(members)} keypoints",
                )
        if spec["groups_required"] > len(spec["groups"]):
            raise ConfigError(path, f"classes.{cls}.groups_required", "more than the groups defined")
    return data


def _cube_rotations() -> np.ndarray:
    """The 24 proper rotations mapping the coordinate axes onto themselves (signed permutations)."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            for row, (col, s) in enumerate(zip(perm, signs, strict=True)):
                m[row, col] = s
            if np.linalg.det(m) > 0:
                out.append(m)
    return np.stack(out)


def keypoint_symmetries(keypoints: np.ndarray, tol: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Permutations (P, K) and rotations (P, 3, 3) among the 24 axis-preserving rotations that map
    the keypoint set onto itself (identity first, duplicate permutations dropped)."""
    perms, rots = [], []
    for rot in _cube_rotations():
        moved = keypoints @ rot.T
        d = np.linalg.norm(moved[:, None, :] - keypoints[None, :, :], axis=-1)
        perm = d.argmin(axis=1)
        # moved[i] = keypoints[perm[i]]: the symmetric pose sees keypoint i where perm[i] was.
        is_symmetry = np.all(d[np.arange(len(keypoints)), perm] < tol) and len(set(perm.tolist())) == len(
            perm
        )
        if is_symmetry and not any(np.array_equal(perm, p) for p in perms):
            perms.append(perm)
            rots.append(rot)
    order = sorted(range(len(perms)), key=lambda i: not np.array_equal(perms[i], np.arange(len(keypoints))))
    return np.stack([perms[i] for i in order]), np.stack([rots[i] for i in order])


def _model(
    name: str,
    cls: str,
    dims: dict[str, float],
    prims: tuple[Primitive, ...],
    spec: Mapping[str, Any],
    parts: Mapping[str, Any],
) -> CadModel:
    scale = np.array([dims[s] for s in spec["scale"]])
    names = tuple(spec["keypoints"])
    kps = np.array([spec["keypoints"][n] for n in names], dtype=float) * scale
    perms, rots = keypoint_symmetries(kps, tol=1e-9 + 1e-6 * float(np.abs(kps).max()))
    vis = Visibility(
        groups={g: tuple(names.index(m) for m in members) for g, members in spec["groups"].items()},
        group_min_visible=spec["group_min_visible"],
        groups_required=spec["groups_required"],
        radius=spec["visibility_radius"],
        min_points=spec["min_points"],
    )
    return CadModel(
        name=name,
        object_class=cls,
        dims=dims,
        primitives=prims,
        keypoint_names=names,
        keypoints=kps,
        visibility=vis,
        symmetries=perms,
        sample_density=parts["sample_density"],
        min_samples=parts["min_samples"],
        max_samples=parts["max_samples"],
        symmetry_rotations=rots,
    )


def strut_layout(length: float, parts: Mapping[str, Any]) -> dict[str, float]:
    """Axial positions along a strut of ``length`` (end a at 0): tube ends and fitting centres."""
    half, fl = parts["corner_size"] / 2, parts["fitting_length"]
    return {
        "tube_a": half + fl,
        "tube_b": length - half - fl,
        "fitting_a": half + fl / 2,
        "fitting_b": length - half - fl / 2,
        "tube_centre": length / 2,
    }


def build_models(
    bay_width: float,
    strut_lengths: Mapping[str, float],
    parts: Mapping[str, Any] | None = None,
    keypoints: Mapping[str, Mapping[str, Any]] | None = None,
) -> dict[str, CadModel]:
    """All CAD models for a mission's geometry (``strut_lengths`` as the mission's geometry lists them)."""
    parts = parts if parts is not None else load_parts()
    kp = keypoints if keypoints is not None else load_keypoints()
    models: dict[str, CadModel] = {}
    rt, rf, fl = parts["tube_radius"], parts["fitting_radius"], parts["fitting_length"]
    for kind, length in strut_lengths.items():
        if kind == "cross_frame_side":  # a cross frame's sides belong to the cross frame model
            continue
        lay = strut_layout(length, parts)
        half_len = (lay["tube_b"] - lay["tube_a"]) / 2
        if half_len <= 0:
            raise ValueError(f"strut {kind} of {length} m is too short for its end fittings")
        models[f"strut_tube/{kind}"] = _model(
            f"strut_tube/{kind}",
            "strut_tube",
            {"radius": rt, "half_length": half_len},
            (Segment((0, 0, -half_len), (0, 0, half_len), rt),),
            kp["strut_tube"],
            parts,
        )
    models["end_fitting"] = _model(
        "end_fitting",
        "end_fitting",
        {"radius": rf, "half_length": fl / 2},
        (Segment((0, 0, -fl / 2), (0, 0, fl / 2), rf, flat_ends=True),),
        kp["end_fitting"],
        parts,
    )
    hw, half, rc = bay_width / 2, parts["corner_size"] / 2, parts["cross_frame_tube_radius"]
    corners = [np.array([x, y, 0.0]) for x, y in ((-hw, -hw), (hw, -hw), (hw, hw), (-hw, hw))]
    sides = []
    for i, c in enumerate(corners):
        d = corners[(i + 1) % 4] - c
        u = d / np.linalg.norm(d)
        sides.append(Segment(tuple(c + u * half), tuple(corners[(i + 1) % 4] - u * half), rc))
    models["cross_frame"] = _model(
        "cross_frame", "cross_frame", {"radius": rc, "half_width": hw}, tuple(sides), kp["cross_frame"], parts
    )
    models["corner_joint"] = _model(
        "corner_joint",
        "corner_joint",
        {"half_size": half},
        (Box((0.0, 0.0, 0.0), (half, half, half)),),
        kp["corner_joint"],
        parts,
    )
    rr, rl = parts["rivet_radius"], parts["rivet_length"]
    models["rivet"] = _model(
        "rivet",
        "rivet",
        {"radius": rr, "half_length": rl / 2},
        (Segment((0, 0, -rl / 2), (0, 0, rl / 2), rr, flat_ends=True),),
        kp["rivet"],
        parts,
    )
    return models


def models_for_mission(mission: Any, **kw: Any) -> dict[str, CadModel]:
    """:func:`build_models` for a loaded :class:`tlt_common.mission.Mission`."""
    return build_models(mission.bay_width, mission.strut_lengths, **kw)


__all__ = [
    "CLASSES",
    "KEYPOINTS_FILE",
    "PARTS_FILE",
    "CadModel",
    "Visibility",
    "build_models",
    "keypoint_symmetries",
    "load_keypoints",
    "load_parts",
    "models_for_mission",
    "strut_layout",
]
