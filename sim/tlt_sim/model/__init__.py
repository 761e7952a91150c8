"""The MuJoCo model of the EDU: MJCF generation, the scene, assembly physics, cameras, scenarios.

MuJoCo picks its OpenGL back end when it is first imported, so the default (OSMesa, offscreen on
the CPU) is set here, before any module of this package imports it; ``MUJOCO_GL`` set by the
caller (``egl`` on a GPU machine) wins.
"""

import os

os.environ.setdefault("MUJOCO_GL", "osmesa")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
