"""The collision model one arm plans in: its own links, the end effector, the carried part, and the
world around it (lifter frame, tower as built so far, dispensers, the other arm).

Reads shapes given in the world frame (:class:`Capsule`, :class:`Box`) in named groups that the
caller replaces as the world changes (``set_group``), and the arm's current configuration on each
query. Collision checking goes through pinocchio's ``GeometryModel`` and coal: the arm's links are
capsules on the joints of the DH chain, the end effector is boxes on the flange, the carried part
capsules on the flange (``attach``). ``computeCollisions`` then runs forward kinematics and every
pair test in one C++ call, tens of microseconds a configuration for this scene
(docs/motion-planning.md compares it with a numpy capsule-capsule version, which is slower once the
Python call overhead and the boxes are counted).

Every shape is inflated by ``padding`` so that a path checked at a finite resolution keeps a
margin. A query never changes the scene; a changed group rebuilds the model on the next query.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from tlt_common.geometry.transforms import rot_x
from tlt_common.geometry.ur10e import ALPHA, A, D, Ur10eKinematics, pinocchio_model

# Link capsule radii of the UR10e (outer radius of the joint housings and tubes), m.
DEFAULT_LINK_RADII = (0.08, 0.065, 0.055, 0.047, 0.047, 0.045)


@dataclass(frozen=True)
class Capsule:
    """A segment from ``p0`` to ``p1`` swept by a sphere of ``radius`` (m)."""

    name: str
    p0: tuple[float, float, float]
    p1: tuple[float, float, float]
    radius: float


@dataclass(frozen=True)
class Box:
    """A box of full extents ``size`` (m) centred at ``pose`` (4x4)."""

    name: str
    pose: np.ndarray
    size: tuple[float, float, float]


Shape = Capsule | Box


def _segment_frame(p0: np.ndarray, p1: np.ndarray) -> tuple[np.ndarray, float]:
    """Pose of a coal capsule (axis z, centred) spanning p0..p1, and its length."""
    axis = p1 - p0
    length = float(np.linalg.norm(axis))
    t = np.eye(4)
    t[:3, 3] = (p0 + p1) / 2.0
    if length > 1e-12:
        z = axis / length
        helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = np.cross(helper, z)
        x /= np.linalg.norm(x)
        t[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    return t, length


def arm_link_segments(kin: Ur10eKinematics, q: Sequence[float]) -> list[tuple[np.ndarray, np.ndarray]]:
    """World end points of the six link capsules of an arm at ``q`` (as the scene models them)."""
    frames = kin.link_frames(q)
    out = []
    for i in range(6):
        # Link i runs from DH frame i-1 along its z by d_i, then along x by a_i (the DH product
        # after the joint rotation); one capsule from the joint to the far end covers it.
        start = frames[i] @ _rz(q[i])
        p0 = start[:3, 3]
        p1 = (start @ np.array([A[i], 0.0, D[i], 1.0]))[:3]
        out.append((p0, p1))
    return out


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    t = np.eye(4)
    t[:2, :2] = [[c, -s], [s, c]]
    return t


class CollisionScene:
    """Collision checks of one arm against its world.

    ``kin`` places the arm (base and tool); ``link_radii`` are the six link capsule radii;
    ``ee_boxes`` the end effector as ``(name, pose in the flange frame, size)``; ``padding`` (m) is
    added to every shape. ``allowed`` lists (arm part, world shape) name pairs never tested, such as
    ("link_1", "<arm>/pedestal") for the pedestal the arm stands on. ``contact_groups`` names the
    groups the end effector and the carried part may touch (the tower, during the last straight
    move onto a joint, as MoveIt allows the gripper to touch the object it places); the arm's
    links are still checked against them. ``in_collision(q)`` is the planner's test;
    ``first_collision(q)`` names the pair for failure reasons.
    """

    def __init__(
        self,
        kin: Ur10eKinematics,
        *,
        link_radii: Sequence[float] = DEFAULT_LINK_RADII,
        ee_boxes: Iterable[tuple[str, np.ndarray, Sequence[float]]] = (),
        padding: float = 0.01,
        name: str = "arm",
        allowed: Iterable[tuple[str, str]] = (),
        contact_groups: Iterable[str] = (),
    ) -> None:
        if len(link_radii) != 6:
            raise ValueError(f"expected six link radii, got {len(link_radii)}")
        self.kin = kin
        self.name = name
        self.padding = float(padding)
        self.link_radii = tuple(float(r) for r in link_radii)
        self.ee_boxes = [
            (n, np.asarray(p, dtype=float), tuple(float(s) for s in size)) for n, p, size in ee_boxes
        ]
        self.model = pinocchio_model(kin.base, kin.tool)
        self.data = self.model.createData()
        self._groups: dict[str, list[Shape]] = {}
        self._attached: list[Capsule] = []
        self._dirty = True
        self._geom_model: pin.GeometryModel | None = None
        self._geom_data: pin.GeometryData | None = None
        self._manager = None
        self.allowed = {(a, b) for a, b in allowed}
        self.contact_groups = frozenset(contact_groups)
        self.checks = 0

    # ----- scene editing -----
    def set_group(self, group: str, shapes: Iterable[Shape]) -> None:
        """Replace the obstacles of ``group`` (world frame), e.g. "tower", "other_arm"."""
        self._groups[group] = list(shapes)
        self._dirty = True

    def group(self, group: str) -> list[Shape]:
        return list(self._groups.get(group, []))

    def set_other_arm(
        self,
        kin: Ur10eKinematics,
        q: Sequence[float],
        radii: Sequence[float] | None = None,
        ee_half_length: float = 0.4,
        ee_depth: float = 0.1,
        ee_radius: float = 0.1,
    ) -> None:
        """Put another arm at configuration ``q`` into the scene: its link capsules and one capsule
        along its end effector bar (flange x, ``ee_depth`` below the flange)."""
        radii = self.link_radii if radii is None else radii
        shapes: list[Shape] = []
        for i, (p0, p1) in enumerate(arm_link_segments(kin, q)):
            shapes.append(Capsule(f"other_arm/link_{i + 1}", tuple(p0), tuple(p1), float(radii[i])))
        flange = kin.base @ kin.flange(q)
        a = (flange @ np.array([-ee_half_length, 0.0, ee_depth, 1.0]))[:3]
        b = (flange @ np.array([ee_half_length, 0.0, ee_depth, 1.0]))[:3]
        shapes.append(Capsule("other_arm/ee", tuple(a), tuple(b), ee_radius))
        self.set_group("other_arm", shapes)

    def attach(self, part: Iterable[Capsule]) -> None:
        """Carry ``part``: capsules given in the tool frame move with the tool from now on."""
        self._attached = list(part)
        self._dirty = True

    def detach(self) -> None:
        self._attached = []
        self._dirty = True

    @property
    def attached(self) -> list[Capsule]:
        return list(self._attached)

    # ----- model -----
    def _build(self) -> None:
        gm = pin.GeometryModel()
        pad = self.padding
        robot: list[int] = []
        link_ids: list[int] = []
        for i in range(6):
            joint = i + 1
            p0 = np.zeros(3)
            p1 = np.array([A[i], 0.0, D[i]])
            placement, length = _segment_frame(p0, p1)
            geom = coal.Capsule(self.link_radii[i] + pad, max(length, 1e-4))
            gid = gm.addGeometryObject(
                pin.GeometryObject(f"{self.name}/link_{joint}", joint, pin.SE3(placement), geom)
            )
            link_ids.append(gid)
            robot.append(gid)
        # The flange is the DH frame 6: joint 6 frame then Tz(d6) Rx(alpha6).
        flange = np.eye(4)
        flange[:3, :3] = rot_x(ALPHA[5])
        flange[:3, 3] = [A[5], 0.0, D[5]]
        ee_ids = []
        for name, pose, size in self.ee_boxes:
            geom = coal.Box(*(s + 2 * pad for s in size))
            gid = gm.addGeometryObject(
                pin.GeometryObject(f"{self.name}/ee/{name}", 6, pin.SE3(flange @ pose), geom)
            )
            ee_ids.append(gid)
            robot.append(gid)
        part_ids = []
        tool = flange @ self.kin.tool
        for cap in self._attached:
            p0 = (tool @ np.array([*cap.p0, 1.0]))[:3]
            p1 = (tool @ np.array([*cap.p1, 1.0]))[:3]
            placement, length = _segment_frame(p0, p1)
            geom = coal.Capsule(cap.radius + pad, max(length, 1e-4))
            gid = gm.addGeometryObject(pin.GeometryObject(f"carried/{cap.name}", 6, pin.SE3(placement), geom))
            part_ids.append(gid)
        world: list[tuple[int, str, str]] = []
        for group, shapes in self._groups.items():
            for shape in shapes:
                world.append((gm.addGeometryObject(_world_object(shape, pad)), shape.name, group))
        pairs: list[tuple[int, int]] = []
        tools = set(ee_ids + part_ids)
        prefix = f"{self.name}/"
        for m in link_ids + ee_ids + part_ids:
            short = gm.geometryObjects[m].name.removeprefix(prefix)
            for w, wname, group in world:
                if (short, wname) in self.allowed or (m in tools and group in self.contact_groups):
                    continue
                pairs.append((m, w))
        # Self collision: links three or more apart in the chain; the end effector and the carried
        # part against the base, upper arm and forearm (the wrist links touch them by design).
        for a in range(6):
            for b in range(a + 3, 6):
                pairs.append((link_ids[a], link_ids[b]))
        for gid in ee_ids + part_ids:
            for a in range(3):
                pairs.append((link_ids[a], gid))
        for a, b in pairs:
            gm.addCollisionPair(pin.CollisionPair(a, b))
        self._geom_model = gm
        self._geom_data = gm.createData()
        # A broad phase culls far pairs (box-box overlap of their AABBs) before coal's narrow phase:
        # several times faster than testing every pair, with the same answers (tested). Of coal's
        # managers, the naive one (every AABB pair, no tree) is the fastest on this scene of about
        # a hundred objects: 31 us against the dynamic AABB tree's 54 us on the configurations of
        # a planning request: at this size the tree does not pay for itself (docs/motion-planning.md).
        self._manager = pin.BroadPhaseManager_NaiveCollisionManager(self.model, gm, self._geom_data)
        self._dirty = False

    def _ensure(self) -> tuple[pin.GeometryModel, pin.GeometryData]:
        if self._dirty or self._geom_model is None:
            self._build()
        assert self._geom_model is not None and self._geom_data is not None
        return self._geom_model, self._geom_data

    # ----- queries -----
    def in_collision(self, q: Sequence[float] | np.ndarray) -> bool:
        """True when the arm at ``q`` touches the world or itself (padding included)."""
        self._ensure()
        self.checks += 1
        return bool(
            pin.computeCollisions(self.model, self.data, self._manager, np.asarray(q, dtype=float), True)
        )

    def in_collision_all_pairs(self, q: Sequence[float] | np.ndarray) -> bool:
        """:meth:`in_collision` without the broad phase: every pair through coal (the reference)."""
        gm, gd = self._ensure()
        return bool(pin.computeCollisions(self.model, self.data, gm, gd, np.asarray(q, dtype=float), True))

    def first_collision(self, q: Sequence[float] | np.ndarray) -> tuple[str, str] | None:
        """Names of the first colliding pair at ``q``, or None when it is free."""
        gm, gd = self._ensure()
        if not pin.computeCollisions(self.model, self.data, gm, gd, np.asarray(q, dtype=float), False):
            return None
        for k, result in enumerate(gd.collisionResults):
            if result.isCollision():
                pair = gm.collisionPairs[k]
                return gm.geometryObjects[pair.first].name, gm.geometryObjects[pair.second].name
        return None

    def segment_free(self, q0: np.ndarray, q1: np.ndarray, resolution: float) -> bool:
        """True when every configuration on the joint-space line q0..q1 is free.

        Checked at ``resolution`` rad (largest joint step) between samples, both ends included,
        in bisection order so that a collision in the middle is found early.
        """
        return self.segment_collision(q0, q1, resolution) is None

    def segment_collision(self, q0: np.ndarray, q1: np.ndarray, resolution: float) -> np.ndarray | None:
        """The first colliding sample found on q0..q1 (bisection order), or None if all are free."""
        q0 = np.asarray(q0, dtype=float)
        q1 = np.asarray(q1, dtype=float)
        span = float(np.max(np.abs(q1 - q0)))
        n = max(1, int(np.ceil(span / resolution)))
        for k in _bisection_order(n):
            q = q0 + (q1 - q0) * (k / n)
            if self.in_collision(q):
                return q
        return None


def _bisection_order(n: int) -> list[int]:
    """0..n, ends first, then midpoints of ever finer halvings."""
    order = [0, n]
    seen = {0, n}
    intervals = [(0, n)]
    while intervals:
        nxt = []
        for a, b in intervals:
            if b - a < 2:
                continue
            m = (a + b) // 2
            if m not in seen:
                seen.add(m)
                order.append(m)
            nxt.append((a, m))
            nxt.append((m, b))
        intervals = nxt
    return order


def _world_object(shape: Shape, pad: float) -> pin.GeometryObject:
    if isinstance(shape, Capsule):
        placement, length = _segment_frame(
            np.asarray(shape.p0, dtype=float), np.asarray(shape.p1, dtype=float)
        )
        geom = coal.Capsule(shape.radius + pad, max(length, 1e-4))
    elif isinstance(shape, Box):
        placement = np.asarray(shape.pose, dtype=float)
        geom = coal.Box(*(s + 2 * pad for s in shape.size))
    else:
        raise TypeError(f"unknown shape {shape!r}")
    return pin.GeometryObject(shape.name, 0, pin.SE3(placement), geom)


def box_at(name: str, centre: Sequence[float], size: Sequence[float], yaw: float = 0.0) -> Box:
    """An upright box of full extents ``size`` at ``centre`` turned by ``yaw`` about z."""
    pose = _rz(yaw)
    pose[:3, 3] = centre
    return Box(name, pose, (float(size[0]), float(size[1]), float(size[2])))


__all__ = [
    "DEFAULT_LINK_RADII",
    "Box",
    "Capsule",
    "CollisionScene",
    "Shape",
    "arm_link_segments",
    "box_at",
]
