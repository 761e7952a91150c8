"""Assembly physics of the twin: grasps, gripper holds and rivets.

Everything that joins two bodies is an equality constraint declared inactive by the generator
and switched on here with the bodies' pose at that instant, so nothing jumps:

* grasp ``grasp/<arm>/<part>`` (weld EE-part): when both grasp jaws close past the point where they
  meet a tube and a part's grasp line lies within ``grasp_reach`` of the EE's, roughly parallel,
  with both jaws on its tube. The part is drawn onto the EE's grasp line but keeps where it lies
  along it (a diagonal is held off its middle). The jaws then stop on the tube (their range is
  narrowed), so the servo positions show the grasp.
  Opening the jaws releases it; a part that nothing else holds then falls.
* Top Gripper ``top/<i>/<cf>`` and Active Gripper ``active/<i>/<cf>`` (connect at corner i): when
  the pin or latch passes its engaged position with a cross frame corner within reach.
* a rivet gun loads when its muzzle is inserted at a rivet dispenser's pickup that has rivets left.
* rivet ``rivet/<strut>/<cf>`` (weld): when a loaded rivet gun fires with a strut end and a cross
  frame corner both within ``rivet_reach`` of the gun; ``foundation/<i>/<cf>`` when a corner is at
  the foundation pad instead.

Scenario faults act here too: a grasp that slips lets go after its time, a part taken off-centre
sits in the grasp with its offset (and so is placed out of tolerance).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from tlt_common.geometry.transforms import rotation_to_mujoco_quat
from tlt_sim.model import names
from tlt_sim.model.generate import HIDDEN_GROUP, PART_BIT, RIVET_GROUP, ModelInfo, PartInfo

_PARALLEL_COS = np.cos(np.radians(20.0))
# Jaw angles (rad) short of the contact angle at which they count as closed on a part, and as
# open again (the gap between the two keeps a jaw resting on a tube from flickering).
JAW_CLOSED, JAW_OPEN = 0.03, 0.15


@dataclass(frozen=True)
class GraspFit:
    """An EE's grasp line against one of a part's: the distance between the lines (m), the angle
    (deg), how far the jaws reach past the part's tube (m, <= 0 when both close on it) and the
    part's line (point, direction in the part's frame)."""

    distance: float
    angle_deg: float
    overhang: float
    line: tuple[np.ndarray, np.ndarray]

    def catches(self, reach: float) -> bool:
        """Closing jaws take the part."""
        return self.distance <= reach and self.overhang <= 0.0


@dataclass
class RivetShot:
    """What one trigger of a rivet gun did."""

    arm: str
    side: str
    time: float
    loaded: bool
    joined: list[str] = field(default_factory=list)  # equality names switched on


@dataclass(frozen=True)
class Release:
    """An arm letting go of a part: the sim time, and the part's world pose at that instant (before
    it settles or falls), for the twin's record of where parts were placed."""

    arm: str
    part: str
    time: float
    position: np.ndarray
    rotation: np.ndarray


class Assembly:
    """Grasp, hold and rivet state on top of a model and its data (see module docstring)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, info: ModelInfo) -> None:
        self.m, self.d, self.info = model, data, info
        ee = info.edu["end_effector"]
        self.ee = ee
        self.eq = {model.equality(i).name: i for i in range(model.neq)}
        self._qadr = {n: int(model.jnt_qposadr[model.joint(n).id]) for n in names.all_actuated_joints()}
        self._site = lambda name: int(model.site(name).id)
        self._body = lambda name: int(model.body(name).id)
        self.parts_by_body = {p.body: p for p in info.parts.values()}
        self._jaw_range = {
            (arm, s): int(model.joint(names.grasp_joint(arm, s)).id) for arm in names.ARMS for s in ("a", "b")
        }
        self.reset()

    # -- state -------------------------------------------------------------------------------
    def reset(self) -> None:
        self.d.eq_active[:] = 0
        self.held: dict[str, str | None] = dict.fromkeys(names.ARMS)
        self._closed: dict[str, bool] = dict.fromkeys(names.ARMS, False)
        self._grasps: dict[str, int] = dict.fromkeys(names.ARMS, 0)
        self._slip_at: dict[str, float] = {}
        self.grasped_at: dict[str, float] = {}  # sim time of each arm's latest grasp
        self.pins: list[str | None] = [None] * 4
        self.latches: list[str | None] = [None] * 4
        self.loaded: dict[tuple[str, str], bool] = {(a, s): False for a in names.ARMS for s in ("a", "b")}
        self.rivets_left = {
            n: (0 if n in self.info.scenario.empty else d.count)
            for n, d in self.info.mission.dispensers.items()
            if d.part_kind == "rivet"
        }
        self.state = dict.fromkeys(self.info.parts, "stowed")  # stowed, grasped, placed, dropped
        self.shots: list[RivetShot] = []
        self.releases: list[Release] = []  # the twin takes them as they come (Twin.tick)
        self._watch()
        self._pending = True  # evaluate the rules once on the next update whatever moved
        for jid in self._jaw_range.values():
            self.m.jnt_range[jid, 1] = self.ee["jaw_range"][1]
        for part in self.info.parts.values():
            self._set_falling(part, False)
            for end in ("a", "b"):
                gid = mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_GEOM, f"{part.body}/rivet_{end}")
                if gid >= 0:
                    self.m.geom_group[gid] = HIDDEN_GROUP

    def q(self, joint: str) -> float:
        return float(self.d.qpos[self._qadr[joint]])

    def site_pos(self, name: str) -> np.ndarray:
        return self.d.site_xpos[self._site(name)].copy()

    def body_pose(self, body: str) -> tuple[np.ndarray, np.ndarray]:
        b = self._body(body)
        return self.d.xpos[b].copy(), self.d.xmat[b].reshape(3, 3).copy()

    def part_point(self, part: PartInfo, local: np.ndarray) -> np.ndarray:
        pos, rot = self.body_pose(part.body)
        return pos + rot @ local

    def active(self, prefix: str = "") -> list[str]:
        return [n for n, i in self.eq.items() if self.d.eq_active[i] and n.startswith(prefix)]

    # -- equality switching ------------------------------------------------------------------
    def _weld(
        self,
        name: str,
        point: np.ndarray,
        shift2: np.ndarray | None = None,
        pose2: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """Switch weld ``name`` on at world ``point``, holding body 2 where it is now (or at
        ``pose2``, a world position and rotation it is drawn to), shifted by ``shift2`` in its frame."""
        i = self.eq[name]
        b1, b2 = self.m.eq_obj1id[i], self.m.eq_obj2id[i]
        x1, r1 = self.d.xpos[b1], self.d.xmat[b1].reshape(3, 3)
        x2, r2 = pose2 if pose2 is not None else (self.d.xpos[b2], self.d.xmat[b2].reshape(3, 3))
        anchor2 = r2.T @ (point - x2)
        if shift2 is not None:
            anchor2 = anchor2 - shift2
        q1, q2 = rotation_to_mujoco_quat(r1), rotation_to_mujoco_quat(r2)
        rel = np.zeros(4)
        neg = np.zeros(4)
        mujoco.mju_negQuat(neg, q1)
        mujoco.mju_mulQuat(rel, neg, q2)
        self.m.eq_data[i, 0:3] = anchor2
        self.m.eq_data[i, 3:6] = r1.T @ (point - x1)
        self.m.eq_data[i, 6:10] = rel
        self.d.eq_active[i] = 1

    def connect(self, name: str, point: np.ndarray) -> None:
        """Switch connect ``name`` on at world ``point``, both bodies where they are now."""
        i = self.eq[name]
        b1, b2 = self.m.eq_obj1id[i], self.m.eq_obj2id[i]
        for k, b in ((0, b1), (3, b2)):
            self.m.eq_data[i, k : k + 3] = self.d.xmat[b].reshape(3, 3).T @ (point - self.d.xpos[b])
        self.d.eq_active[i] = 1

    def switch_off(self, name: str) -> None:
        """Lift equality ``name``: the bodies it joined move apart freely again."""
        self.d.eq_active[self.eq[name]] = 0

    # -- per-step update ---------------------------------------------------------------------
    def _watch(self) -> None:
        """Index arrays of the joints whose crossings the rules react to (one gather per step)."""
        ag, tg, ee = self.info.edu["active_grippers"], self.info.edu["top_grippers"], self.ee
        joints = [names.top_gripper(i) for i in range(4)] + [names.active_gripper(i) for i in range(4)]
        thresholds = [tg["engaged_above"]] * 4 + [ag["engaged_above"]] * 4
        for arm in names.ARMS:
            joints += [names.grasp_joint(arm, "a"), names.grasp_joint(arm, "b")]
            thresholds += [ee["jaw_contact"] - JAW_CLOSED] * 2
        self._watch_adr = np.array([self._qadr[j] for j in joints])
        self._watch_thr = np.array(thresholds)
        self._watch_low = self._watch_thr.copy()
        self._watch_low[8:] = ee["jaw_contact"] - JAW_OPEN  # jaws: hysteresis before counting as open
        self._set_watch_state(np.zeros(len(joints), dtype=bool))

    def _set_watch_state(self, state: np.ndarray) -> None:
        # Each watched joint keeps its state while below its upper bound and at or above its lower
        # one: two comparisons per step instead of recomputing the state (this runs every step).
        self._watch_state = state
        self._watch_upper = np.where(state, np.inf, self._watch_thr)
        self._watch_lower = np.where(state, self._watch_low, -np.inf)

    def update(self) -> None:
        """Apply grasp, gripper and slip rules to the present state (called after each step)."""
        q = self.d.qpos[self._watch_adr]
        if self._pending or self._slip_at or (q >= self._watch_upper).any() or (q < self._watch_lower).any():
            self._set_watch_state(np.where(self._watch_state, q >= self._watch_low, q >= self._watch_thr))
            self._pending = False
            self._apply_rules()

    def _apply_rules(self) -> None:
        for arm in names.ARMS:
            self._update_grasp(arm)
        ag, tg = self.info.edu["active_grippers"], self.info.edu["top_grippers"]
        for i in range(4):
            self._update_hold(
                i,
                "top",
                self.pins,
                self.q(names.top_gripper(i)) >= tg["engaged_above"],
                f"{names.top_gripper(i)}/tip",
                tg["reach"],
            )
            self._update_hold(
                i,
                "active",
                self.latches,
                self.q(names.active_gripper(i)) >= ag["engaged_above"],
                f"{names.active_gripper(i)}/tip",
                ag["reach"],
            )

    def _update_hold(
        self, i: int, kind: str, holds: list[str | None], engaged: bool, tip: str, reach: float
    ) -> None:
        if engaged and holds[i] is None:
            p = self.site_pos(tip)
            best = self._nearest_corner(p, i, reach)
            if best is not None:
                self.connect(f"{kind}/{i}/{best}", self.site_pos(names.corner_site(best, i)))
                holds[i] = best
        elif not engaged and holds[i] is not None:
            self.switch_off(f"{kind}/{i}/{holds[i]}")
            holds[i] = None
            self._settle_parts()

    def _nearest_corner(self, p: np.ndarray, corner: int, reach: float) -> str | None:
        best, dist = None, reach
        for cf in self.info.cross_frames:
            dd = float(np.linalg.norm(self.site_pos(names.corner_site(cf, corner)) - p))
            if dd <= dist:
                best, dist = cf, dd
        return best

    def _update_grasp(self, arm: str) -> None:
        contact = self.ee["jaw_contact"]
        qa, qb = self.q(names.grasp_joint(arm, "a")), self.q(names.grasp_joint(arm, "b"))
        closed = min(qa, qb) >= contact - JAW_CLOSED
        opened = min(qa, qb) < contact - JAW_OPEN
        if closed and not self._closed[arm]:
            self._closed[arm] = True
            self._try_grasp(arm)
        elif opened and self._closed[arm]:
            self._closed[arm] = False
            self.release(arm)
        when = self._slip_at.get(arm)
        if when is not None and self.d.time >= when:
            del self._slip_at[arm]
            self.release(arm)

    def grasp_line(self, arm: str) -> tuple[np.ndarray, np.ndarray]:
        """Midpoint of the two grippers' grasp points and the direction between them (world)."""
        a, b = self.site_pos(f"{arm}/grip_a"), self.site_pos(f"{arm}/grip_b")
        return (a + b) / 2, (b - a) / np.linalg.norm(b - a)

    def grasp_fit(self, arm: str, part: PartInfo) -> GraspFit:
        """How ``arm``'s grasp line meets the nearest roughly parallel grasp line of ``part``
        (distance inf when none is)."""
        centre, axis = self.grasp_line(arm)
        jaws = float(np.linalg.norm(self.site_pos(f"{arm}/grip_b") - self.site_pos(f"{arm}/grip_a"))) / 2
        pos, rot = self.body_pose(part.body)
        best = GraspFit(np.inf, 90.0, np.inf, part.grasps[0])
        for point, direction in part.grasps:
            u = rot @ direction
            cos = min(1.0, abs(float(axis @ u)))
            if cos < _PARALLEL_COS:
                continue
            rel = centre - (pos + rot @ point)
            along = float(rel @ u)
            dist = float(np.linalg.norm(rel - along * u))
            if dist < best.distance:
                best = GraspFit(dist, float(np.degrees(np.arccos(cos))), abs(along) + jaws - part.grasp_span,
                                (point, direction))  # fmt: skip
        return best

    def _try_grasp(self, arm: str) -> None:
        centre, axis = self.grasp_line(arm)
        best, fit = None, None
        for part in self.info.parts.values():
            if self.state[part.name] in ("grasped",) or self._held_by_other(part.body, arm):
                continue
            f = self.grasp_fit(arm, part)
            if f.catches(self.ee["grasp_reach"]) and (fit is None or f.distance < fit.distance):
                best, fit = part, f
        if best is None:
            return
        offset = self.info.scenario.offsets.get(best.name)
        shift = np.asarray(offset) if offset is not None else None
        seated = self._seated(best, fit.line, centre, axis)
        self._weld(f"grasp/{arm}/{best.body}", centre, shift2=shift, pose2=seated)
        self.held[arm] = best.body
        self.state[best.name] = "grasped"
        for side in ("a", "b"):  # the jaws now stop on the tube
            self.m.jnt_range[self._jaw_range[(arm, side)], 1] = self.ee["jaw_contact"]
        self._set_falling(best, False)
        self._grasps[arm] += 1
        self.grasped_at[arm] = float(self.d.time)
        slip = self.info.scenario.slips.get((arm, self._grasps[arm]))
        if slip is not None:
            self._slip_at[arm] = self.d.time + slip

    def _seated(
        self, part: PartInfo, line: tuple[np.ndarray, np.ndarray], centre: np.ndarray, axis: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Where closing jaws draw ``part``: its grasp ``line`` (point, direction in the part) onto
        the EE's, turned the least, its point staying where it lies along the EE's line."""
        pos, rot = self.body_pose(part.body)
        point, direction = line
        along = float((pos + rot @ point - centre) @ axis)
        current = rot @ direction
        target = axis if float(current @ axis) >= 0 else -axis
        turn = np.cross(current, target)
        sin, cos = float(np.linalg.norm(turn)), float(current @ target)
        align = np.eye(3)
        if sin > 1e-12:
            k = turn / sin
            kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            align = np.eye(3) + sin * kx + (1 - cos) * kx @ kx
        seated = align @ rot
        return centre + along * axis - seated @ point, seated

    def _held_by_other(self, body: str, arm: str) -> bool:
        return any(h == body for a, h in self.held.items() if a != arm)

    def release(self, arm: str) -> str | None:
        """Let go of what ``arm`` holds; a part nothing else holds falls. Returns its body name."""
        body = self.held[arm]
        for side in ("a", "b"):
            self.m.jnt_range[self._jaw_range[(arm, side)], 1] = self.ee["jaw_range"][1]
        if body is None:
            return None
        pos, rot = self.body_pose(body)
        self.releases.append(Release(arm, self.parts_by_body[body].name, float(self.d.time), pos, rot))
        self.switch_off(f"grasp/{arm}/{body}")
        self.held[arm] = None
        self._slip_at.pop(arm, None)
        self._settle_parts()
        return body

    def _attached(self) -> set[str]:
        """Bodies held by the machine: payload, anything grasped, and all joined to them."""
        links: dict[str, set[str]] = {}
        roots = {"payload"}
        for n in self.active():
            kind = n.split("/", 1)[0]
            i = self.eq[n]
            b1 = self.m.body(self.m.eq_obj1id[i]).name
            b2 = self.m.body(self.m.eq_obj2id[i]).name
            if kind in ("top", "active", "foundation", "grasp"):
                roots.add(b2 if kind == "grasp" else b1)
            else:
                links.setdefault(b1, set()).add(b2)
                links.setdefault(b2, set()).add(b1)
        seen, todo = set(), list(roots)
        while todo:
            b = todo.pop()
            if b not in seen:
                seen.add(b)
                todo.extend(links.get(b, ()))
        return seen

    def _settle_parts(self) -> None:
        """Parts no longer attached to anything fall (gravity back on); attached ones are placed."""
        attached = self._attached()
        for part in self.info.parts.values():
            st = self.state[part.name]
            if st == "stowed":
                continue
            if part.body in attached:
                if st != "grasped" or part.body not in self.held.values():
                    self.state[part.name] = "placed"
            else:
                self.state[part.name] = "dropped"
                self._set_falling(part, True)

    def _set_falling(self, part: PartInfo, falling: bool) -> None:
        b = self._body(part.body)
        self.m.body_gravcomp[b] = 0.0 if falling else 1.0
        first, count = self.m.body_geomadr[b], self.m.body_geomnum[b]
        self.m.geom_contype[first : first + count] = PART_BIT if falling else 0
        self.m.body_contype[b] = PART_BIT if falling else 0  # the broadphase filters by body first

    # -- rivets ------------------------------------------------------------------------------
    def _show_loaded_rivet(self, arm: str, side: str, shown: bool) -> None:
        # A geom with zero alpha is left out of rendering and of segmentation alike.
        self.m.geom_rgba[self.m.geom(names.loaded_rivet_geom(arm, side)).id, 3] = 1.0 if shown else 0.0

    def load_rivet(self, arm: str, side: str) -> bool:
        """Take a rivet into gun ``side`` if its muzzle is within ``rivet_reach`` of the pickup of
        a rivet dispenser that has one (the gun inserted into the feeder)."""
        if self.loaded[(arm, side)]:
            return True
        gun = self.site_pos(names.rivet_gun_site(arm, side))
        for name, left in self.rivets_left.items():
            if left <= 0:
                continue
            if np.linalg.norm(self.site_pos(f"dispenser/{name}/pickup") - gun) <= self.ee["rivet_reach"]:
                self.rivets_left[name] -= 1
                self.loaded[(arm, side)] = True
                self._show_loaded_rivet(arm, side, True)
                return True
        return False

    def fire_rivet(self, arm: str, side: str) -> RivetShot:
        """Trigger gun ``side``: rivet every strut end and cross frame corner at the gun together."""
        shot = RivetShot(arm, side, float(self.d.time), self.loaded[(arm, side)])
        self.shots.append(shot)
        if not shot.loaded:
            return shot
        self.loaded[(arm, side)] = False
        self._show_loaded_rivet(arm, side, False)
        gun = self.site_pos(names.rivet_gun_site(arm, side))
        reach = self.ee["rivet_reach"]
        corners = [
            (cf, i)
            for cf in self.info.cross_frames
            for i in range(4)
            if np.linalg.norm(self.site_pos(names.corner_site(cf, i)) - gun) <= reach
        ]
        # Strut ends at the gun not yet riveted to the frame whose corner is there.
        ends = [
            (part, end, cf, i)
            for part in self.info.parts.values()
            if part.kind != "cross_frame" and self.state[part.name] != "stowed"
            for end, local in part.ends.items()
            if np.linalg.norm(self.part_point(part, local) - gun) <= reach
            for cf, i in corners
            if not self.d.eq_active[self.eq[f"rivet/{part.body}/{cf}"]]
        ]
        for part, end, cf, i in ends:
            name = self.rivet(part, end, cf, i)
            if name is not None:
                shot.joined.append(name)
        if not ends:  # nothing left to join to the frame here: a foundation rivet, if on a pad
            top = self.info.edu["site"]["foundation_top"]
            for cf, i in corners:
                pad = np.array([*_corner_xy(self.info, i), top])
                name = f"foundation/{i}/{cf}"
                near = np.linalg.norm(self.site_pos(names.corner_site(cf, i)) - pad) <= reach
                if near and not self.d.eq_active[self.eq[name]]:
                    self.connect(name, self.site_pos(names.corner_site(cf, i)))
                    shot.joined.append(name)
        self._settle_parts()
        return shot

    def rivet(self, part: PartInfo, end: str, cross_frame: str, corner: int) -> str | None:
        """Join ``part``'s ``end`` to ``cross_frame`` at ``corner`` as they lie now, and show the rivet.
        Returns the weld's name, or None if they were already joined."""
        name = f"rivet/{part.body}/{cross_frame}"
        gid = mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_GEOM, f"{part.body}/rivet_{end}")
        if gid >= 0:
            self.m.geom_group[gid] = RIVET_GROUP
        if self.d.eq_active[self.eq[name]]:
            return None
        self._weld(name, self.site_pos(names.corner_site(cross_frame, corner)))
        return name


def _corner_xy(info: ModelInfo, i: int) -> tuple[float, float]:
    x, y = names.CORNER_XY[i]
    return x * info.mission.bay_width, y * info.mission.bay_width


__all__ = ["Assembly", "Release", "RivetShot"]
