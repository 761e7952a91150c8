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
  the foundation pad instead. Each joint the shot reaches turns out as where the gun stands and the
  scenario's rivet faults say (:mod:`tlt_sim.model.rivet_outcomes`): good, a softer weld, or none;
  its head shows accordingly (:mod:`tlt_sim.model.rivet_heads`) and the outcome is recorded
  (:attr:`Assembly.rivet_joints`, the twin's truth).

Scenario faults act here too: a grasp that slips lets go after its time, a part taken off-centre
sits in the grasp with its offset (and so is placed out of tolerance), a rivet fault spoils the
joint of its shot.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from tlt_common.geometry.transforms import rotation_to_mujoco_quat
from tlt_sim.model import names
from tlt_sim.model.generate import PART_BIT, ModelInfo, PartInfo
from tlt_sim.model.rivet_heads import RivetHeads
from tlt_sim.model.rivet_outcomes import EFFECTS, SHOT_KINDS, RivetJoint, bar_angle_deg, judge_geometry

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
    outcomes: list[RivetJoint] = field(default_factory=list)  # each joint the shot reached


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
        self.heads = RivetHeads(model, info, info.edu)
        self._solref0 = model.eq_solref.copy()  # as built: a good rivet's, the holds'
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
        self.rivet_joints: dict[str, RivetJoint] = {}  # equality name -> the joint's latest outcome
        self.rivet_log: list[RivetJoint] = []  # every outcome as it comes (the twin takes them)
        self._shots_at: dict[str, int] = {}  # equality name -> shots that reached it
        self.m.eq_solref[:] = self._solref0
        self.heads.reset()
        self.releases: list[Release] = []  # the twin takes them as they come (Twin.tick)
        self._watch()
        self._pending = True  # evaluate the rules once on the next update whatever moved
        for jid in self._jaw_range.values():
            self.m.jnt_range[jid, 1] = self.ee["jaw_range"][1]
        for part in self.info.parts.values():
            self._set_falling(part, False)

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

    def slip(self, name: str) -> float:
        """How far (m) the two points equality ``name`` holds together stand apart now (0 when it
        is inactive): a soft weld or connect giving under load."""
        i = self.eq[name]
        equality = self.d.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
        rows = np.nonzero(equality & (self.d.efc_id == i))[0]
        return float(np.linalg.norm(self.d.efc_pos[rows[:3]])) if len(rows) else 0.0

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
        """Trigger gun ``side``: rivet every strut end and cross frame corner at the gun together
        (a foundation corner when no strut end is left to rivet there), each joint as its outcome
        says. An end already joined well is not riveted again; one an earlier rivet left bad is,
        anew, by a shot that finds nothing new to rivet (:meth:`_rivet_targets`)."""
        shot = RivetShot(arm, side, float(self.d.time), self.loaded[(arm, side)])
        self.shots.append(shot)
        if not shot.loaded:
            return shot
        targets = self._rivet_targets(arm, side)
        plan = self.info.scenario.rivets
        numbers = [self._shots_at.get(t.equality, 0) + 1 for t in targets]
        injected = [
            plan.injected(t.member, t.joint, n) if t.member else None
            for t, n in zip(targets, numbers, strict=True)
        ]
        failed = next((k for k in injected if k in SHOT_KINDS), None)
        if failed is None or EFFECTS[failed].spent:
            self.loaded[(arm, side)] = False
            self._show_loaded_rivet(arm, side, False)
        if failed == "no_rivet":
            shot.loaded = False  # the rivet had left the gun before it fired
        for target, number, fault in zip(targets, numbers, injected, strict=True):
            self._shots_at[target.equality] = number
            if failed is not None:
                kind, cause, reason = failed, "injected", f"the whole shot: {failed}"
            elif fault is not None:
                kind, cause, reason = fault, "injected", "scenario"
            else:
                kind, reason = judge_geometry(target.offset_m, target.angle_deg, self.info.edu["rivets"])
                cause = "geometry"
            record = RivetJoint(
                target.member, target.joint, target.equality, kind, cause, reason, number,
                arm, side, shot.time, target.offset_m, target.angle_deg,
            )  # fmt: skip
            if failed is None and target.end is not None:
                part, end, cf, corner = target.end
                # The head faces the gun: the fitting's side towards the EE's flange.
                facing = -self.body_pose(names.ee_body(arm))[1][:, 2]
                if self.rivet(part, end, cf, corner, kind, facing) is not None:
                    shot.joined.append(target.equality)
            elif failed is None:
                cf, corner = target.corner
                if self._join_foundation(target.equality, self.site_pos(names.corner_site(cf, corner)), kind):
                    shot.joined.append(target.equality)
            shot.outcomes.append(record)
            self.rivet_log.append(record)
            # A shot that set no rivet leaves the joint as an earlier rivet left it.
            if failed is None or target.equality not in self.rivet_joints:
                self.rivet_joints[target.equality] = record
        self._settle_parts()
        mujoco.mj_kinematics(self.m, self.d)  # the heads where the shot left them, for a frame now
        return shot

    def _rivet_targets(self, arm: str, side: str) -> list[_Target]:
        """The joints a shot of gun ``side`` of ``arm`` reaches, as it stands now: strut ends at the
        gun that no rivet reached yet, riveted to the frame whose corner is there; else joints at the
        gun an earlier rivet left bad (a second shot); else a corner on a foundation pad. A later
        member's shot at a corner so leaves an earlier member's bad joint there as it is."""
        gun = self.site_pos(names.rivet_gun_site(arm, side))
        bar = self.grasp_line(arm)[1]
        reach = self.ee["rivet_reach"]
        corners = [
            (cf, i)
            for cf in self.info.cross_frames
            for i in range(4)
            if np.linalg.norm(self.site_pos(names.corner_site(cf, i)) - gun) <= reach
        ]
        fresh: list[_Target] = []
        again: list[_Target] = []
        for part in self.info.parts.values():
            if part.kind == "cross_frame" or self.state[part.name] == "stowed":
                continue
            for end, local in part.ends.items():
                point = self.part_point(part, local)
                if np.linalg.norm(point - gun) > reach:
                    continue
                for cf, i in corners:
                    name = f"rivet/{part.body}/{cf}"
                    if self._well_joined(name):
                        continue
                    joint = self._mission_joint(self.site_pos(names.corner_site(cf, i)))
                    axis = self.part_point(part, part.ends["b"]) - self.part_point(part, part.ends["a"])
                    target = _Target(
                        name, self._member_at(part, end, joint), joint,
                        float(np.linalg.norm(point - gun)), bar_angle_deg(bar, axis), (part, end, cf, i),
                    )  # fmt: skip
                    (again if name in self.rivet_joints else fresh).append(target)
        top = self.info.edu["site"]["foundation_top"]
        pads: list[_Target] = []
        for cf, i in corners:
            pad = np.array([*_corner_xy(self.info, i), top])
            corner = self.site_pos(names.corner_site(cf, i))
            name = f"foundation/{i}/{cf}"
            if np.linalg.norm(corner - pad) <= reach and not self._well_joined(name):
                joint = self._mission_joint(corner)
                member = next(
                    (
                        m.id
                        for m in self.info.mission.members
                        if m.kind == "foundation_rivet" and m.joints[0][0] == joint
                    ),
                    "",
                )
                offset = float(np.linalg.norm(corner - gun))
                angle = bar_angle_deg(bar, self.body_pose(cf)[1][:, 2])  # the tower axis
                target = _Target(name, member, joint, offset, angle, corner=(cf, i))
                (again if name in self.rivet_joints else pads).append(target)
        return fresh or again or pads

    def _well_joined(self, name: str) -> bool:
        record = self.rivet_joints.get(name)
        return bool(self.d.eq_active[self.eq[name]]) and (record is None or record.good)

    def _mission_joint(self, point: np.ndarray) -> str:
        """The mission's joint at world ``point`` on the tower as it stands ('' if none is near)."""
        pos, rot = self.body_pose("payload")
        best, dist = "", self.ee["rivet_reach"]
        for joint, local in self.info.mission.joints.items():
            d = float(np.linalg.norm(pos + rot @ np.asarray(local, dtype=float) - point))
            if d <= dist:
                best, dist = joint, d
        return best

    def _member_at(self, part: PartInfo, end: str, joint: str) -> str:
        """The mission's member of ``part``'s kind that ``part`` stands as, its ``end`` at ``joint``
        ('' if it stands as none): of the members riveted there, the one whose other joint lies
        nearest its other end."""
        if not joint:
            return ""
        other = self.part_point(part, part.ends["b" if end == "a" else "a"])
        best, dist = "", 2 * self.ee["rivet_reach"]
        for member in self.info.mission.members:
            points = dict(member.joints)
            if member.kind != part.kind or joint not in points:
                continue
            for far in points:
                if far != joint:
                    d = float(np.linalg.norm(self._tower_point(points[far]) - other))
                    if d <= dist:
                        best, dist = member.id, d
        return best

    def _tower_point(self, local: tuple[float, float, float]) -> np.ndarray:
        pos, rot = self.body_pose("payload")
        return pos + rot @ np.asarray(local, dtype=float)

    def _set_solref(self, name: str, kind: str) -> None:
        i = self.eq[name]
        softer = EFFECTS[kind].softer
        self.m.eq_solref[i] = self._solref0[i] if softer is None else self.info.edu["rivets"][softer]

    def _join_foundation(self, name: str, point: np.ndarray, kind: str) -> bool:
        """Connect a frame corner to its foundation pad at ``point`` as ``kind`` leaves it; True if
        joined."""
        if not EFFECTS[kind].joins:
            self.switch_off(name)
            return False
        self._set_solref(name, kind)
        self.connect(name, point)
        return True

    def rivet(
        self,
        part: PartInfo,
        end: str,
        cross_frame: str,
        corner: int,
        kind: str = "good",
        facing: np.ndarray | None = None,
    ) -> str | None:
        """Join ``part``'s ``end`` to ``cross_frame`` at ``corner`` as they lie now, as a rivet of
        outcome ``kind`` does (:data:`~tlt_sim.model.rivet_outcomes.EFFECTS`), and show its head on
        the side of the fitting ``facing`` (world) points to (where the generator put it: None).
        Returns the weld's name, or None if nothing was joined anew (joined well already, or a kind
        that joins nothing)."""
        name = f"rivet/{part.body}/{cross_frame}"
        if self._well_joined(name):
            return None
        effect = EFFECTS[kind]
        local = None if facing is None else self.body_pose(part.body)[1].T @ facing
        self.heads.show(part.body, end, effect.head, local)
        if not effect.joins:
            self.switch_off(name)
            return None
        self._set_solref(name, kind)
        self._weld(name, self.site_pos(names.corner_site(cross_frame, corner)))
        return name

    def record_joint(self, record: RivetJoint) -> None:
        """Note a joint's outcome made without a shot (a staged rivet)."""
        self._shots_at[record.equality] = record.shot
        self.rivet_joints[record.equality] = record
        self.rivet_log.append(record)


@dataclass(frozen=True)
class _Target:
    """A joint a shot reaches: its equality, mission member and joint ('' where unknown), the gun's
    offset from the hole and its bar's angle to the member's axis; a strut end (part, end, frame,
    corner) or a foundation corner (frame, corner)."""

    equality: str
    member: str
    joint: str
    offset_m: float
    angle_deg: float
    end: tuple[PartInfo, str, str, int] | None = None
    corner: tuple[str, int] = ("", 0)


def _corner_xy(info: ModelInfo, i: int) -> tuple[float, float]:
    x, y = names.CORNER_XY[i]
    return x * info.mission.bay_width, y * info.mission.bay_width


__all__ = ["Assembly", "Release", "RivetShot"]
