"""The one reader of parameters files (config/rwa_monitor.yaml format) for every command.

A parameters file is the ROS 2 ``--params-file`` format: node blocks, each with
``ros__parameters``, and a ``/**`` block shared by every node. :func:`block_values`
merges them the way ROS does (the node's block over ``/**``) and checks the result with
the node's :class:`~rwa_monitor.core.schema.Schema`: a name of the node's own block that
the schema lacks is refused with the nearest valid name; a ``/**`` name that no schema
knows is refused too, while one that belongs to another node is left to that node.
Floats written without a dot (``1e-5``) are accepted. Every failure is a one-line
:class:`ConfigError` naming the file.
"""

from __future__ import annotations

import pathlib
from typing import Any, Mapping

from rwa_monitor import paths
from rwa_monitor.core.schema import Schema, SCHEMAS, SHARED_NAMES
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry.yaml_file import read_yaml

SHARED_BLOCK = '/**'


def read_parameters_file(path: str | pathlib.Path | None) -> dict[str, Any]:
    """Return the node blocks of a parameters file (None: the installed one, if any)."""
    if path is None:
        try:
            path = paths.config_file()
        except FileNotFoundError:
            return {}
    path = paths.installed_or_given(path)     # config/NAME of the docs, for a pip install
    document = read_yaml(path)
    if document is None:
        return {}
    if not isinstance(document, dict):
        raise ConfigError(f'{path}: expected a mapping of node blocks '
                          f'(name: {{ros__parameters: {{...}}}}), got {type(document).__name__}')
    for name in document:
        _parameters_of(document, name, path)
    return document


def _parameters_of(document: Mapping[str, Any], block: str, path: Any) -> dict[str, Any]:
    node = document.get(block)
    if node is None:
        return {}
    if not isinstance(node, dict):
        raise ConfigError(f'{path}: block {block!r} must be a mapping with ros__parameters')
    values = node.get('ros__parameters')
    if values is None:
        return {}
    if not isinstance(values, dict):
        raise ConfigError(f'{path}: {block}: ros__parameters must be a mapping')
    return values


def block_values(document: Mapping[str, Any], schema: Schema, path: Any = 'parameters',
                 ) -> dict[str, Any]:
    """Return the checked values of ``schema``'s node: its block over ``/**``, defaults."""
    shared = _parameters_of(document, SHARED_BLOCK, path)
    known = set(SHARED_NAMES).union(*(s.names() for s in SCHEMAS.values()))
    for name in shared:
        if name not in known:
            raise ConfigError(f'{path}: {SHARED_BLOCK}: unknown parameter {name!r}'
                              f'{schema.nearest(name)}')
    values = {k: v for k, v in shared.items() if k in schema.names()}
    values.update(_parameters_of(document, schema.name, path))
    try:
        return schema.validate(values)
    except ConfigError as err:
        raise ConfigError(f'{path}: {err}') from None


def load_block(path: str | pathlib.Path | None, schema: Schema) -> dict[str, Any]:
    """Return the checked values of ``schema``'s node in a parameters file (or defaults)."""
    where = path if path is not None else 'installed parameters'
    return block_values(read_parameters_file(path), schema, where)
