"""The one YAML reader: safe loading with alias expansion bounded (docs/contracts.md).

Aliases let a few hundred bytes stand for billions of values (an "alias bomb"); the
constructor shares aliased objects, but anything that walks the result (a check, a
message, a copy) expands them. :func:`load_yaml` composes the node graph (cheap: an
alias is a reference to its anchor's node), counts the values the document would have
once every alias is expanded, without expanding anything, and refuses a document above
MAX_VALUES (or one whose aliases make it recursive, or nested deeper than MAX_DEPTH)
before constructing a single Python object. Every failure is a one-line ConfigError
naming the file. Parameters files, calibrations, friction models and recording metadata
are all read through it.
"""

from __future__ import annotations

import os
import pathlib
from typing import Any

import yaml

from rwa_monitor.exceptions import ConfigError

# Far above any file of the package (a calibration: ~2,000 values) and far below harm.
MAX_VALUES = 200_000
MAX_DEPTH = 100
MAX_BYTES = 16 * 1024 * 1024


def expanded_size(root: yaml.Node, limit: int = MAX_VALUES) -> int:
    """Return the number of nodes of ``root`` with aliases expanded (stops above ``limit``).

    Each distinct node is visited once (sizes are memoised on the graph), so the cost is
    the size of the composed graph, not of its expansion. ValueError for a recursive
    document (an alias inside its own anchor) or one nested deeper than MAX_DEPTH.
    """
    sizes: dict[int, int] = {}
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    open_nodes: set[int] = set()
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            open_nodes.discard(key)
            total = 1 + sum(sizes[id(c)] for c in _children(node))
            sizes[key] = min(total, limit + 1)
            continue
        if key in sizes:
            continue
        if key in open_nodes:
            raise ValueError('an alias refers to a node that contains it (recursive)')
        if len(open_nodes) >= MAX_DEPTH:
            raise ValueError(f'nested deeper than {MAX_DEPTH} levels')
        open_nodes.add(key)
        stack.append((node, True))
        stack.extend((c, False) for c in _children(node) if id(c) not in sizes)
    return sizes[id(root)]


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    return []


def load_yaml(text: str, source: str = 'YAML', limit: int = MAX_VALUES) -> Any:
    """Return the safe-loaded document of ``text`` (None if empty); ConfigError if refused."""
    loader = None
    try:
        loader = yaml.SafeLoader(text)
        node = loader.get_single_node()
        if node is None:
            return None
        size = expanded_size(node, limit)
        if size > limit:
            raise ConfigError(f'{source}: refused: its aliases expand to more than {limit} '
                              'values')
        return loader.construct_document(node)
    except ValueError as err:
        if isinstance(err, ConfigError):
            raise
        raise ConfigError(f'{source}: refused: {err}') from None
    except yaml.YAMLError as err:
        first = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise ConfigError(f'{source}: not valid YAML: {first[:200]}') from None
    except RecursionError:
        raise ConfigError(f'{source}: refused: nested too deeply') from None
    finally:
        if loader is not None:
            loader.dispose()


def read_yaml(path: str | os.PathLike, limit: int = MAX_VALUES) -> Any:
    """Read and :func:`load_yaml` a file (ConfigError naming it if unreadable or refused)."""
    try:
        with open(path, 'rb') as handle:
            data = handle.read(MAX_BYTES + 1)
    except OSError as err:
        raise ConfigError(f'{path}: cannot read: {err.strerror or err}') from None
    if len(data) > MAX_BYTES:
        raise ConfigError(f'{path}: refused: larger than {MAX_BYTES // (1024 * 1024)} MiB')
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError:
        raise ConfigError(f'{path}: not a UTF-8 text file') from None
    return load_yaml(text, os.fspath(pathlib.Path(path)), limit)
