"""Reading input files so that bad input never hurts: size-limited, text only, strict YAML.

Every reader here ends in a :class:`~derive.errors.DeriveError` naming the file on any
problem: not a regular file (``/dev/zero``, a folder), too large, not UTF-8 text, an OS
error; YAML that is malformed, nested too deeply, has a duplicate key, or expands (through
aliases) to more nodes than any robot needs (a "billion laughs" file).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

import yaml

from derive.errors import DeriveError

MAX_FILE_BYTES = 16 * 2**20   # a models file or URDF: robots need kilobytes
MAX_YAML_NODES = 500_000      # scalars, lists and mappings after expanding aliases
MAX_YAML_DEPTH = 200          # nesting of lists and mappings


class InputFileError(DeriveError):
    """An input file that cannot be read or parsed; the message names the file."""


def read_bytes(path: str | Path, what: str = "file") -> bytes:
    """The bytes of the regular file ``path`` (at most MAX_FILE_BYTES)."""
    path = Path(path)
    if str(path) in ("", "."):
        raise InputFileError(f"{what}: empty path")
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):  # before opening: a FIFO would block open()
            raise InputFileError(f"{path}: cannot read {what}: not a regular file")
        with open(path, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise InputFileError(f"{path}: cannot read {what}: not a regular file")
            data = f.read(MAX_FILE_BYTES + 1)
    except InputFileError:
        raise
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    if len(data) > MAX_FILE_BYTES:
        raise InputFileError(f"{path}: {what} is larger than {MAX_FILE_BYTES // 2**20} MiB")
    return data


def read_text(path: str | Path, what: str = "file") -> str:
    """The UTF-8 text of the regular file ``path`` (at most MAX_FILE_BYTES)."""
    data = read_bytes(path, what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputFileError(f"{path}: {what} is not UTF-8 text (byte {exc.start})") from None


class StrictLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """yaml.SafeLoader that refuses duplicate keys (the last one would silently win); on libyaml's
    parser where PyYAML has it (5x faster: a 1,000-link models.yaml), the same constructor either way."""


def _mapping(loader: StrictLoader, node: yaml.MappingNode, deep: bool = False):
    seen: dict[Any, yaml.Node] = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = loader.construct_object(key_node, deep=True)
        try:
            duplicate = key in seen
        except TypeError:  # an unhashable key: the base constructor says so
            break
        if duplicate:
            raise yaml.constructor.ConstructorError(
                "while constructing a mapping", node.start_mark, f"duplicate key {key!r}", key_node.start_mark)
        seen[key] = key_node
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)


def _size(data: Any) -> tuple[int, int]:
    """(nodes, depth) of loaded YAML, counting aliases as often as they are used; stops past the limits."""
    nodes, deepest, stack = 0, 0, [(data, 1)]
    while stack:
        item, depth = stack.pop()
        nodes += 1
        deepest = max(deepest, depth)
        if nodes > MAX_YAML_NODES or deepest > MAX_YAML_DEPTH:
            break
        if isinstance(item, dict):
            stack.extend((v, depth + 1) for kv in item.items() for v in kv)
        elif isinstance(item, list):
            stack.extend((v, depth + 1) for v in item)
    return nodes, deepest


def load_yaml(text: str, source: str) -> Any:
    """Parse ``text`` (from ``source``) strictly; InputFileError names the line and the problem."""
    try:
        data = yaml.load(text, Loader=StrictLoader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise InputFileError(f"{source}{where}: malformed YAML: {problem}") from None
    except (RecursionError, MemoryError):
        raise InputFileError(f"{source}: YAML nested too deeply") from None
    except (ValueError, OverflowError) as exc:  # a scalar its constructor cannot build: an int of 5000 digits,
        # a date such as 2024-13-45 (PyYAML raises these unwrapped)
        raise InputFileError(f"{source}: malformed YAML: {str(exc).splitlines()[0].split(';')[0]}") from None
    nodes, depth = _size(data)
    if depth > MAX_YAML_DEPTH:
        raise InputFileError(f"{source}: YAML nested deeper than {MAX_YAML_DEPTH} levels")
    if nodes > MAX_YAML_NODES:
        raise InputFileError(f"{source}: YAML expands to more than {MAX_YAML_NODES} values (aliases?)")
    return data
