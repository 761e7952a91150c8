"""MJCF of the EDU, generated from ``config/twin/edu.yaml``, a mission and a scenario.

:func:`build_model` writes ``edu.xml`` and the AprilTag PNG textures into an output folder and
returns a :class:`ModelInfo` describing what it made (parts, their local geometry, the cross frames
that grippers and rivets can hold). Nothing is compiled here; :mod:`tlt_sim.model.scene` does that.

One builder per assembly, each given the document and the part of the EDU description it needs,
composed by :func:`build_model` (``build``):

``document``: the MJCF skeleton and sections, collision bits and geom groups.
``layout``: the tower's corners, the lifter posts and the levels (the world frame is described there).
``foundation``, ``lifter``, ``camera_mounts``, ``payload``, ``arm``, ``end_effector``,
``dispensers`` (with ``parts``, the loose parts in their slots), ``equalities``.
``info``: :class:`ModelInfo` and :class:`PartInfo`, what was built.

Assembly is by equality constraints (see :mod:`tlt_sim.model.assembly`).
"""

from tlt_sim.model.generate.build import build_model
from tlt_sim.model.generate.dispensers import rack_uprights
from tlt_sim.model.generate.document import ARM_BIT, CLASS_COLOURS, HIDDEN_GROUP, PART_BIT, RIVET_GROUP
from tlt_sim.model.generate.info import ModelInfo, PartInfo

__all__ = [
    "ARM_BIT",
    "CLASS_COLOURS",
    "HIDDEN_GROUP",
    "PART_BIT",
    "RIVET_GROUP",
    "ModelInfo",
    "PartInfo",
    "build_model",
    "rack_uprights",
]
