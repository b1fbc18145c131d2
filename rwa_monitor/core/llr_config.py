"""The LLR detector's configuration: its checked parameters, frozen and typed.

The parameters are defined once, in the ``llr_detector`` block of core/schema.py (name,
default, range, unit, meaning); :meth:`LLRConfig.from_parameters` checks each value with
its :class:`rwa_monitor.core.schema.Param` and the rules between them with
:func:`rwa_monitor.core.schema.llr_resolve`, then keeps the result here under the same
names. The detector's parts (core/llr_changes.py, llr_general.py, llr_samples.py) receive
this object explicitly, together with the state (core/llr_state.py).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from functools import cached_property
import math
import textwrap
from typing import Any

from rwa_monitor.core import llr_stats
from rwa_monitor.core.friction import coulomb_viscous, RegressorSet
from rwa_monitor.core.params import AUTO
from rwa_monitor.core.schema import LLR, llr_resolve

#: The detector's keyword parameters, in the schema's order (``component`` and
#: ``regressors`` are Python-only: a wheel id and a model object).
PARAMETERS = LLR.names(('all',))
DEFAULTS = {name: LLR[name].default for name in PARAMETERS}
# Python-only spellings: None stands for 'auto' (and for 0 = growing reference).
_NONE_IS_AUTO = ('k_verif', 'noise_std', 'noise_ar_max_order', 'noise_fit_samples')


def numpydoc_parameters(indent: str = '    ') -> str:
    """Return the numpydoc entries of :data:`PARAMETERS`, written from the schema.

    For the detector's docstring: name, type, default, the schema's one line of meaning,
    unit and allowed values (core/schema.py).
    """
    lines = []
    for name in PARAMETERS:
        param = LLR[name]
        kind = param.type.__name__ + (" or 'auto'" if param.auto else '')
        lines.append(f'{indent}{name} : {kind}, default {param.default!r}')
        text = f'{param.description} Allowed: {param.allowed()}' + (
            f'; unit {param.unit}.' if param.unit else '.')
        lines += textwrap.wrap(text, 88, initial_indent=2 * indent,
                               subsequent_indent=2 * indent)
    return '\n'.join(lines)


@dataclass(frozen=True)
class LLRConfig:
    """The checked parameters of one LLR detector (core/schema.py ``llr_detector``).

    ``auto`` resolved (``k_verif``, ``noise_ar_max_order``, ``noise_fit_samples`` as
    integers, ``noise_std`` None when estimated), ``reference_max`` None for the growing
    reference. The derived quantities the parts use are properties, named for what they
    are (``ring_length`` is not a window).
    """

    component: str
    window: int
    k_verif: int
    false_alarm_rate: float
    noise_std: float | None
    category_level: float
    category_revisions: int
    refine_change: bool
    min_excitation: float
    max_abs_speed: float
    max_abs_friction: float
    noise_ar_max_order: int
    noise_fit_samples: int
    reference_max: int | None
    noise_speed_model: bool
    regressors: RegressorSet

    @classmethod
    def from_parameters(cls, component: str = 'rw1', regressors: RegressorSet | None = None,
                        **params: Any) -> LLRConfig:
        """Return the configuration of these keyword parameters (ValueError naming one).

        Missing parameters take the schema's defaults; None stands for ``auto`` where a
        parameter has it, ``reference_max`` None for 0 and ``category_level`` None for
        ``false_alarm_rate``.
        """
        if not isinstance(component, str) or not component:
            raise ValueError(f'component must be a non-empty string, got {component!r}')
        if regressors is None:
            regressors = coulomb_viscous()
        if not isinstance(regressors, RegressorSet):
            raise ValueError(f'regressors must be a RegressorSet or None, got {regressors!r}')
        unknown = sorted(set(params) - set(PARAMETERS))
        if unknown:
            raise TypeError(f'unknown LLR parameter {unknown[0]!r}{LLR.nearest(unknown[0])}')
        values = {**DEFAULTS, **params}
        for name in _NONE_IS_AUTO:
            if values[name] is None:
                values[name] = AUTO
        if values['reference_max'] is None:
            values['reference_max'] = 0
        if values['category_level'] is None:
            values['category_level'] = values['false_alarm_rate']
        checked = {name: LLR[name].check(values[name]) for name in PARAMETERS}
        return cls(component=component, regressors=regressors,
                   **llr_resolve(checked, regressors.p))

    def as_dict(self) -> dict[str, Any]:
        """Return the parameters by name (``component`` and ``regressors`` included)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def fingerprint(self) -> dict[str, bool | int | float | str | None]:
        """Return the parameters as scalars: what a saved state is checked against.

        The regressor set by its column names (its callables are code, never saved).
        """
        out = self.as_dict()
        out['regressors'] = ','.join(self.regressors.names)
        return out

    @property
    def p(self) -> int:
        """Number of regressor columns (2: the paper's eq. (1))."""
        return self.regressors.p

    @cached_property
    def paper_model(self) -> bool:
        """True for the paper's model object (the compiled per-sample path)."""
        return self.regressors.is_coulomb_viscous

    @property
    def width(self) -> int:
        """Floats in one prefix-sum row (core/llr_stats.py ``width``)."""
        return llr_stats.width(self.p)

    @property
    def term_width(self) -> int:
        """Floats per sample in the ring of terms: ``(h1, h2, f)`` for p = 2, else a row."""
        return 3 if self.p == 2 else self.width

    @property
    def kernel_ar_order(self) -> int:
        """AR coefficients the kernel arrays hold room for (0: p > 2 whitens in numpy)."""
        return self.noise_ar_max_order if self.p == 2 else 0

    @cached_property
    def log_r(self) -> float:
        """``log(false_alarm_rate)``: Algorithm 1 line 18 compares ``log p_min`` to it."""
        return math.log(self.false_alarm_rate)

    @property
    def noise_var(self) -> float | None:
        """The given noise variance, or None when estimated on the reference."""
        return None if self.noise_std is None else self.noise_std ** 2

    @cached_property
    def z_threshold(self) -> float:
        """Two-sided normal quantile of ``category_level`` (the kind tests)."""
        return llr_stats.z_threshold(self.category_level)

    @cached_property
    def ring_length(self) -> int:
        """Entries of the rings of the last accepted samples (a power of two).

        At least ``2 window + k_verif + 2 + reference_max``: every sample a declaration or
        a sliding reference needs is still in them; the kernel indexes them by mask.
        """
        return 1 << (2 * self.window + self.k_verif + 1 + (self.reference_max or 0)).bit_length()

    @cached_property
    def tail_stride(self) -> int:
        """Samples between two takes of a closed change's ramp sums: the rings' length.

        A closed change (its re-checks done) takes the samples since its last take into
        its tail block when the ring is full of them: at the next take the ring still
        holds every one, and the detector leaves its compiled loop once per
        ``ring_length`` samples instead of once per ``window`` (docs/llr.md "Kinds on
        ramps").
        """
        return self.ring_length

    @property
    def fits_noise(self) -> bool:
        """True if a noise model is fitted on the first samples (AR order or speed model)."""
        return self.noise_ar_max_order > 0 or self.noise_speed_model
