"""Fixtures of the twin tests: an in-process Twin (model + every emulator) on a private run folder.

UR controllers bind fixed ports, so each Twin here answers on its own loopback addresses, away
from 127.0.0.2/.3 that the stand-alone emulators and a developer's twin use.
"""

from __future__ import annotations

import itertools

import pytest
from tlt_sim.model.scene import Scene
from tlt_sim.twin.settings import load_settings
from tlt_sim.twin.simulation import Twin

_hosts = itertools.count(80)


@pytest.fixture
def make_twin(tmp_path):
    made: list[Twin] = []

    def make(scenario=None, **settings) -> Twin:
        n = next(_hosts)
        base = load_settings().replace(ur_hosts={"ur_x": f"127.0.{n}.2", "ur_y": f"127.0.{n}.3"})
        scene = Scene(scenario=scenario, out_dir=tmp_path / f"model{n}")
        twin = Twin(scene, base.replace(**settings), tmp_path / f"run{n}")
        made.append(twin)
        return twin

    yield make
    for twin in made:
        twin.close()
        twin.scene.close()
