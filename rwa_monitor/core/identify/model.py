"""The refined friction model: a configuration snippet and the detectors' RegressorSet.

Snippet (YAML; ``rwa-monitor identify`` writes it as DIR/friction_model.yaml)::

    friction_model:
      wheel: rw1
      noise_std_nm: 5.0e-05
      effects:                       # in the order the selection added them
        - {name: drag, kind: drag, params: {exponent: 2.0}}
      weights: {dry: 1.0e-03, viscous: 5.0e-06, drag: 2.0e-08}

The regressors are model (1)'s ``dry`` and ``viscous`` columns followed by each effect's
columns (effects.regressor_columns, the one definition shared with the selection); a
column is named after its effect (``drag``) or, for effects with several columns,
``<effect>.<column>`` (``periodic.cos``). The weights are the identified values (of the
last segment when jumps were found); the detectors re-estimate them online.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from rwa_monitor.core.identify.effects import regressor_columns
from rwa_monitor.exceptions import ConfigError

KINDS = ('stribeck', 'stribeck_hysteresis', 'presliding', 'presliding_state',
         'frictional_lag', 'stick', 'asymmetric_coulomb', 'drag', 'inertia', 'gravity_load',
         'load_dry', 'gear_ripple', 'aux', 'drift', 'periodic', 'smooth_speed')


def plain(value: Any) -> Any:
    """Return ``value`` with numpy scalars and arrays as Python numbers and lists."""
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def column_names(name: str, kind: str, params: Mapping[str, Any]) -> list[str]:
    """Return the regressor names of one effect."""
    cols = regressor_columns(kind, dict(params))
    return [name] if len(cols) == 1 else [f'{name}.{sub}' for sub, _ in cols]


def snippet(selection) -> dict:
    """Return the ``friction_model`` configuration of a finished selection."""
    fit = selection.final_fit
    nb = len(selection.baseline_names)
    last = nb - 2
    weights = {'dry': float(fit.coef[last]), 'viscous': float(fit.coef[last + 1])}
    effects = []
    for eff in selection.effects:
        names = column_names(eff.name, eff.kind, eff.params)
        weights.update({n: float(c) for n, c in zip(names, fit.coef[eff.columns])})
        effects.append({'name': eff.name, 'kind': eff.kind, 'params': plain(eff.params)})
    return {'friction_model': {'wheel': selection.data.wheel,
                               'noise_std_nm': float(selection.data.noise_floor),
                               'effects': effects, 'weights': weights}}


def _block(cfg: Mapping[str, Any]) -> Mapping[str, Any]:
    if not isinstance(cfg, Mapping):
        raise ConfigError(f'friction_model must be a mapping, got {type(cfg).__name__}')
    return cfg.get('friction_model', cfg)


def regressors_from_config(cfg: Mapping[str, Any]):
    """Return the RegressorSet of a ``friction_model`` snippet (or of its inner block).

    An empty or missing ``effects`` list gives model (1) (core.friction.coulomb_viscous).
    Raise ConfigError naming an unknown effect kind or a missing parameter.
    """
    from rwa_monitor.core.friction import coulomb_viscous, RegressorSet
    block = _block(cfg)
    base = coulomb_viscous()
    names, columns = list(base.names), list(base.columns)
    for i, eff in enumerate(block.get('effects') or []):
        if not isinstance(eff, Mapping) or 'kind' not in eff:
            raise ConfigError(f'friction_model.effects[{i}] needs a kind, got {eff!r}')
        kind = eff['kind']
        if kind not in KINDS:
            raise ConfigError(f'friction_model.effects[{i}].kind must be one of '
                              f'{", ".join(KINDS)}; got {kind!r}')
        params = dict(eff.get('params') or {})
        name = str(eff.get('name', kind))
        try:
            cols = regressor_columns(kind, params)
        except KeyError as err:
            raise ConfigError(f'friction_model.effects[{i}] ({kind}) lacks parameter '
                              f'{err.args[0]}') from None
        names += column_names(name, kind, params)
        columns += [c for _, c in cols]
    return RegressorSet(names, columns)


def aux_channels(cfg: Mapping[str, Any]) -> list[str]:
    """Return the auxiliary channels the model's columns read (the file must have them)."""
    return [e['params']['column'] for e in (_block(cfg).get('effects') or [])
            if e.get('kind') == 'aux']
