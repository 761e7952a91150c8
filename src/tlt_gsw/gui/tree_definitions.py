"""Behaviour-tree shape definitions as files, for the GUI's tree view and the mission job.

The agents send their tree definitions over the link (``tree_definition`` packets, kept in the
archive), so the GUI needs no file to name the nodes. A file still serves where no definition was
sent (an archive recorded before agents sent them, a tree shown without a link):
:func:`write_tree_definition` saves an agent's shape as JSON (the document of
:mod:`tlt_common.bt.shape_definition`), :func:`load_tree_definition` reads it back, and
:class:`TreeDefinitionFiles` re-reads an agent's file when the agent starts sending a new tree
shape. A file that is not a valid definition raises :class:`ConfigError` naming the file.
"""

from __future__ import annotations

import json
from collections.abc import Collection, Mapping
from pathlib import Path

from tlt_common.bt.shape_definition import definition_document
from tlt_common.bt.status_codec import StatusCodecError, TreeShape
from tlt_common.config_schema import ConfigError


def write_tree_definition(shape: TreeShape, path: str | Path, agent: str = "") -> Path:
    """Write ``shape`` as ``{"agent", "shape_hash", "definition"}`` JSON; return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(definition_document(shape, agent), indent=1), encoding="utf-8")
    return path


def load_tree_definition(path: str | Path) -> TreeShape:
    """Read a definition file (the object above, or the bare definition list) into a TreeShape."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(path, "", f"cannot read file: {exc.strerror or exc}") from exc
    except json.JSONDecodeError as exc:
        raise ConfigError(path, "", f"invalid JSON: {exc}") from exc
    definition = data.get("definition") if isinstance(data, dict) else data
    if not isinstance(definition, list):
        raise ConfigError(path, "definition", "expected a list of nodes (TreeShape.definition())")
    try:
        shape = TreeShape.from_definition(definition)
    except StatusCodecError as exc:
        raise ConfigError(path, "definition", str(exc)) from exc
    stated = data.get("shape_hash") if isinstance(data, dict) else None
    if stated is not None and stated != f"{shape.hash:08x}":
        raise ConfigError(
            path, "shape_hash", f"file says {stated}, the definition hashes to {shape.hash:08x}"
        )
    return shape


class TreeDefinitionFiles:
    """Each agent's definition file, re-read when it changes.

    An agent that rebuilds its tree (an ARS swapping branches, a CRS restarted on another mission)
    sends a new shape hash and writes a new definition file; :meth:`changed` notices the new file
    (by modification time and size) so the GUI can name the new tree without a restart. A file
    that does not exist yet is not an error here: the tree view says the definition is missing.
    """

    def __init__(self, paths: Mapping[str, Path]) -> None:
        self.paths = {agent: Path(p) for agent, p in paths.items()}
        self._stamps: dict[str, tuple[float, int]] = {}

    def _stamp(self, agent: str) -> tuple[float, int] | None:
        try:
            info = self.paths[agent].stat()
        except (KeyError, OSError):
            return None
        return info.st_mtime, info.st_size

    def load_present(self, required: Collection[str] = ()) -> dict[str, TreeShape]:
        """Load every file that exists (and every ``required`` agent's, missing or not: ConfigError)."""
        shapes = {}
        for agent, path in self.paths.items():
            stamp = self._stamp(agent)
            if stamp is None and agent not in required:
                continue
            shapes[agent] = load_tree_definition(path)
            self._stamps[agent] = stamp or (0.0, 0)
        return shapes

    def changed(self, agent: str) -> TreeShape | None:
        """The agent's shape if its file is new or changed since last read, else None.

        A file that changed but cannot be read (half written) is tried again on a later call.
        """
        stamp = self._stamp(agent)
        if stamp is None or stamp == self._stamps.get(agent):
            return None
        try:
            shape = load_tree_definition(self.paths[agent])
        except ConfigError:
            return None
        self._stamps[agent] = stamp
        return shape


__all__ = ["TreeDefinitionFiles", "load_tree_definition", "write_tree_definition"]
