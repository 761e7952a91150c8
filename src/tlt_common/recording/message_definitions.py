"""Full ROS 2 message definitions (``ros2msg`` schema text) of a topic type, from installed files.

An MCAP reader decodes CDR bytes only with the definition of the type and of every type it
contains. This module builds that text the way rosbag2 stores it: the root type's ``.msg`` text,
then each dependency once, each after a separator line of 80 ``=`` and a ``MSG: pkg/Type`` line.

It reads the ``.msg``, ``.srv`` and ``.action`` files that ament packages install under
``<prefix>/share/<package>/{msg,srv,action}/`` (prefixes: ``AMENT_PREFIX_PATH`` and the running
interpreter's prefix, which is the venv's, where the wheels and ``tlt_interfaces`` install).
Types derived from a service or an action, which have no file of their own, are cut out of their
parent file: ``X_Request``/``X_Response`` (and ``X_Event``, service introspection) from
``X.srv``; ``X_Goal``/``X_Result``/``X_Feedback`` and the feedback topic's
``X_FeedbackMessage`` (``goal_id`` + ``feedback``) from ``X.action``.

A type whose files cannot be found raises :class:`DefinitionNotFound` naming the type and where
it looked.
"""

from __future__ import annotations

import os
import re
import sys
from collections.abc import Iterable
from pathlib import Path

SEPARATOR = "=" * 80
PRIMITIVE_TYPES = frozenset(
    {
        "bool",
        "byte",
        "char",
        "float32",
        "float64",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "string",
        "wstring",
    }
)
_CONSTANT = re.compile(r"^\w+\s*=")  # "NAME = value" after the type; a field is "name [default]"
_SECTION_SPLIT = re.compile(r"^---\s*$", re.MULTILINE)
_ACTION_PARTS = {"Goal": 0, "Result": 1, "Feedback": 2}
_SERVICE_PARTS = {"Request": 0, "Response": 1}


class DefinitionNotFound(LookupError):
    """No installed interface file defines the type (or one of the types it contains)."""


def default_share_dirs() -> list[Path]:
    """Each ``<prefix>/share`` of ``AMENT_PREFIX_PATH``, then the interpreter's, that exists."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    dirs: list[Path] = []
    for prefix in prefixes:
        share = Path(prefix) / "share"
        if share.is_dir() and share not in dirs:
            dirs.append(share)
    return dirs


def split_type_name(type_name: str) -> tuple[str, str, str]:
    """``pkg/msg/Name`` -> ``(pkg, "msg", Name)``; ``pkg/Name`` means ``pkg/msg/Name``."""
    parts = type_name.split("/")
    if len(parts) == 2 and all(parts):
        return parts[0], "msg", parts[1]
    if len(parts) == 3 and all(parts):
        return parts[0], parts[1], parts[2]
    raise DefinitionNotFound(f"{type_name!r} is not a ROS type name (pkg/msg/Name)")


def _strip_comment(line: str) -> str:
    # A '#' inside a string constant's value is not a comment, but such constants never name a
    # type, so cutting there cannot hide a dependency.
    return line.split("#", 1)[0].strip()


def field_base_type(line: str) -> str | None:
    """The type a field line uses, without array or bound suffixes; None for blank, comment and
    constant lines and for primitive types."""
    text = _strip_comment(line)
    if not text:
        return None
    parts = text.split(None, 1)
    if len(parts) < 2:
        return None
    type_token, rest = parts
    if _CONSTANT.match(rest):
        return None  # constants are always of a primitive type
    base = type_token.split("[", 1)[0].split("<=", 1)[0]
    if base in PRIMITIVE_TYPES:
        return None
    return base


def dependencies(text: str, package: str) -> list[str]:
    """The complex types a definition's fields use, as ``pkg/Type``, in order of first use."""
    found: list[str] = []
    for line in text.splitlines():
        base = field_base_type(line)
        if base is None:
            continue
        if "/" not in base:
            base = f"{package}/{base}"
        else:
            pkg, _, name = split_type_name(base)
            base = f"{pkg}/{name}"
        if base not in found:
            found.append(base)
    return found


def first_field_is_header(text: str) -> bool:
    """Whether the first field of a definition is a ``std_msgs/Header`` (its stamp comes first in
    the CDR bytes, so a recorder can read it without decoding the message)."""
    for line in text.splitlines():
        stripped = _strip_comment(line)
        if not stripped:
            continue
        type_token, _, rest = stripped.partition(" ")
        if _CONSTANT.match(rest.strip()):
            continue  # constants take no place in the serialized message
        return type_token in ("std_msgs/Header", "std_msgs/msg/Header")
    return False


class MessageDefinitionSource:
    """Looks up and caches message definitions in a list of ``share`` directories."""

    def __init__(self, share_dirs: Iterable[str | Path] | None = None) -> None:
        self._share_dirs = [Path(d) for d in (share_dirs if share_dirs is not None else default_share_dirs())]
        self._own_text: dict[str, str] = {}
        self._full_text: dict[str, str] = {}

    @property
    def share_dirs(self) -> list[Path]:
        return list(self._share_dirs)

    def _find_file(self, package: str, kind: str, name: str) -> Path | None:
        for share in self._share_dirs:
            path = share / package / kind / f"{name}.{kind}"
            if path.is_file():
                return path
        return None

    def _derived(self, package: str, name: str) -> str | None:
        """Text of a type cut out of a ``.srv`` or ``.action`` file, or None if no file has it."""
        base, sep, part = name.rpartition("_")
        if not sep or not base:
            return None
        if part in _ACTION_PARTS or part == "FeedbackMessage":
            path = self._find_file(package, "action", base)
            if path is not None:
                if part == "FeedbackMessage":
                    return f"unique_identifier_msgs/UUID goal_id\n{base}_Feedback feedback\n"
                sections = _SECTION_SPLIT.split(path.read_text(encoding="utf-8"))
                if len(sections) == 3:
                    return sections[_ACTION_PARTS[part]].strip("\n") + "\n"
        if part in _SERVICE_PARTS or part == "Event":
            path = self._find_file(package, "srv", base)
            if path is not None:
                if part == "Event":
                    return (
                        "service_msgs/ServiceEventInfo info\n"
                        f"{base}_Request[<=1] request\n{base}_Response[<=1] response\n"
                    )
                sections = _SECTION_SPLIT.split(path.read_text(encoding="utf-8"))
                if len(sections) == 2:
                    return sections[_SERVICE_PARTS[part]].strip("\n") + "\n"
        return None

    def own_text(self, type_name: str) -> str:
        """The definition of one type alone (its file's text), without its dependencies."""
        package, kind, name = split_type_name(type_name)
        key = f"{package}/{name}"
        cached = self._own_text.get(key)
        if cached is not None:
            return cached
        path = self._find_file(package, "msg", name) if kind == "msg" else None
        text = path.read_text(encoding="utf-8") if path is not None else self._derived(package, name)
        if text is None:
            where = ", ".join(str(d) for d in self._share_dirs) or "no share directory"
            raise DefinitionNotFound(f"no definition of {type_name} under {where}")
        self._own_text[key] = text
        return text

    def full_text(self, type_name: str) -> str:
        """The ``ros2msg`` schema text of a type: its own text, then every dependency once."""
        cached = self._full_text.get(type_name)
        if cached is not None:
            return cached
        package, _, name = split_type_name(type_name)
        parts = [self.own_text(type_name).rstrip("\n") + "\n"]
        seen = {f"{package}/{name}"}
        # Depth-first, in order of first use, like rosbag2; a guard bounds malformed cycles.
        stack = list(reversed(dependencies(parts[0], package)))
        while stack:
            dep = stack.pop()
            if dep in seen:
                continue
            seen.add(dep)
            if len(seen) > 1000:
                raise DefinitionNotFound(f"{type_name}: more than 1000 nested types")
            dep_pkg = dep.split("/", 1)[0]
            text = self.own_text(dep)
            parts.append(f"{SEPARATOR}\nMSG: {dep}\n{text.rstrip(chr(10))}\n")
            stack.extend(reversed([d for d in dependencies(text, dep_pkg) if d not in seen]))
        full = "".join(parts)
        self._full_text[type_name] = full
        return full
