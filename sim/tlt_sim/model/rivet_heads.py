"""The rivet heads a camera sees on the struts: none, seated, proud, or in the wrong hole.

Every strut end carries a hidden head (``<part>/rivet_<end>``, a sphere on its end fitting) and
a hidden shank (``<part>/rivet_<end>#1``, the same instance to the segmentation); the generator
puts the head where a good rivet seats. :class:`RivetHeads` shows them as a shot left them
(:data:`tlt_sim.model.rivet_outcomes.EFFECTS`): a proud or partly gripping head stands out of
the fitting by ``rivets.proud_height`` / ``partial_grip_height`` with its shank showing between;
a head in the wrong hole sits ``rivets.wrong_hole_offset`` along the fitting towards the tube. A
shot's head faces the gun (the fitting's side towards the EE), so the EE camera beside it sees it.
Moving a geom here changes the model (``geom_pos``, ``geom_size``): only rendering sees it, since
heads and shanks collide with nothing.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from tlt_sim.model.generate import HIDDEN_GROUP, RIVET_GROUP, ModelInfo


class RivetHeads:
    """Heads and shanks of every strut end of ``model`` (built from ``info`` for machine ``edu``)."""

    def __init__(self, model: mujoco.MjModel, info: ModelInfo, edu: dict[str, Any]) -> None:
        self.m, self.rivets = model, edu["rivets"]
        self._radius = edu["parts"]["rivet_radius"]
        self._fitting = edu["parts"]["fitting_radius"]
        # (part body, end) -> head geom id, shank geom id, the hole's point on the fitting's axis and
        # the unit vector along that axis towards the tube (both in the part's frame).
        self._ends: dict[tuple[str, str], tuple[int, int, np.ndarray, np.ndarray]] = {}
        for part in info.parts.values():
            for end, local in part.ends.items():
                head = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{part.body}/rivet_{end}")
                if head < 0:  # an end without its fitting has no hole to rivet
                    continue
                shank = model.geom(f"{part.body}/rivet_{end}#1").id
                # The generator seats a head on the fitting's +x side.
                centre = model.geom_pos[head] - self._fitting * _X
                along = centre - np.asarray(local, dtype=float)
                along -= (along @ _X) * _X
                self._ends[(part.body, end)] = (head, shank, centre, along / np.linalg.norm(along))
        self.reset()

    def reset(self) -> None:
        """Every head hidden, back where a good rivet seats."""
        for key in self._ends:
            self.show(*key, None)

    def show(self, body: str, end: str, head: str | None, facing: np.ndarray | None = None) -> None:
        """Show the head at ``end`` of part ``body`` as ``head`` (``seated``, ``proud``,
        ``partial``, ``wrong_hole``; None hides it), on the side of the fitting that ``facing``
        (part frame; the fitting's +x side when None) points to: the side the gun fired from."""
        if (body, end) not in self._ends:
            return
        hid, sid, centre, along = self._ends[(body, end)]
        out = _X if facing is None else np.asarray(facing, dtype=float) - (facing @ along) * along
        norm = float(np.linalg.norm(out))
        out = out / norm if norm > 1e-9 else _X
        m = self.m
        rise = {"proud": self.rivets["proud_height"], "partial": self.rivets["partial_grip_height"]}.get(
            head or "", 0.0
        )
        seated = centre + self._fitting * out
        m.geom_group[hid] = HIDDEN_GROUP if head is None else RIVET_GROUP
        m.geom_pos[hid] = seated + rise * out
        if head == "wrong_hole":
            m.geom_pos[hid] = seated + self.rivets["wrong_hole_offset"] * along
        # The shank runs from inside the fitting (a head's radius in from the seated centre) to the
        # head's centre; it shows only under a head that stands out.
        length = self._radius + rise
        m.geom_group[sid] = RIVET_GROUP if rise > 0 else HIDDEN_GROUP
        m.geom_pos[sid] = seated - self._radius * out + out * length / 2
        m.geom_size[sid, 1] = length / 2
        mujoco.mju_quatZ2Vec(m.geom_quat[sid], out)


_X = np.array([1.0, 0.0, 0.0])

__all__ = ["RivetHeads"]
