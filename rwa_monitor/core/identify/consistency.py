"""Consistency of the effects identified on sibling wheels of one file.

Identical wheels on one bus should need the same named effects. Two ways to compare:

- Wheels identified one by one (:func:`compare_effects`): the majority set of effect
  names (ties: the set of the first wheel among them) is the reference; a wheel whose
  set differs is flagged with what it lacks and what it adds.
- Wheels identified jointly (joint.py: one common set chosen on the pooled evidence): a
  wheel is flagged when its own data contradict its siblings, by either test:

  * **extra** (its evidence for an effect the siblings do without): the wheel's refitted
    residual fails the structure tests and one step of the single-wheel selection
    (select.py) on it, at the family level alpha / K for K wheels, adds an effect: the
    wheel alone would need it (Bonferroni p, validation LR and BIC gain all pass).
  * **missing** (its evidence against an effect the siblings share): with the shared
    nonlinear parameters, the wheel's weights b_k differ from the mean of its siblings'
    b_s by the two-sample Wald statistic W = d' (C_k + C_s)^-1 d, d = b_k - b_s, chi^2
    with the effect's column count, at level alpha / (K E) for E common effects, in the
    direction of a smaller effect (d . b_s < 0); and the wheel's own likelihood-ratio
    test of the effect (leaving its columns out of its refitted model) has p > alpha:
    its data exclude the siblings' size of the effect and show none of it.

  When more wheels contradict a common effect than show it (own p <= alpha), the
  effect is the minority's: the wheels that show it are flagged (``extra``) instead.
  A weight that differs while the effect is still present is not a contradiction:
  parameter values may differ legitimately (wear, temperature) and are shown side by
  side.

Effect names are compared with a wheel's own channel prefix replaced by ``<wheel>``
(``aux:rw1_motor_torque:dry`` and ``aux:rw2_motor_torque:dry`` are the same effect) and
listed in the vocabulary's order (effects.canonical_order).
"""

from __future__ import annotations

from collections import Counter

import numpy as np
from scipy import stats

from rwa_monitor.core.identify.effects import canonical_order

WHEEL = '<wheel>'


def sibling_name(name: str, wheel: str) -> str:
    """Return an effect name with the wheel's own channel prefix replaced by ``<wheel>``."""
    prefix = f'aux:{wheel}_'
    return f'aux:{WHEEL}_' + name[len(prefix):] if name.startswith(prefix) else name


def compare_effects(effects: dict[str, list[str]]) -> dict:
    """Return the reference effect set and the wheels that differ from it.

    ``effects`` maps wheel id -> names of its identified effects (wheels identified one
    by one).
    """
    if not effects:
        return {'rule': 'majority', 'reference': [], 'consistent': True, 'flagged': {},
                'agreeing': []}
    sets = {w: frozenset(sibling_name(n, w) for n in names) for w, names in effects.items()}
    counts = Counter(sets.values())
    top = max(counts.values())
    reference = next(s for s in sets.values() if counts[s] == top)
    flagged = {w: {'missing': canonical_order(reference - s),
                   'extra': canonical_order(s - reference)}
               for w, s in sets.items() if s != reference}
    return {'rule': 'majority', 'reference': canonical_order(reference),
            'consistent': not flagged, 'flagged': flagged,
            'agreeing': sorted(w for w, s in sets.items() if s == reference)}


def weaker_than_siblings(items: list, own: list, level: float, alpha: float
                         ) -> list[dict | None]:
    """Return, per wheel, the "missing" test of one common effect (module docstring).

    ``items[k]``: wheel k's (weights, covariance) of the effect with the shared
    parameters, or None (the effect is not testable on it); ``own[k]``: its own
    likelihood-ratio evidence (``p_value``), or None. A wheel without siblings that have
    the effect gets None.
    """
    out: list[dict | None] = []
    for k, item in enumerate(items):
        siblings = [it for j, it in enumerate(items) if j != k and it is not None]
        if item is None or not siblings or own[k] is None:
            out.append(None)
            continue
        b_k, c_k = np.atleast_1d(item[0]), np.atleast_2d(item[1])
        b_s = np.mean([np.atleast_1d(b) for b, _ in siblings], axis=0)
        c_s = sum(np.atleast_2d(c) for _, c in siblings) / len(siblings) ** 2
        d = b_k - b_s
        wald = float(d @ np.linalg.pinv(c_k + c_s) @ d)
        p_wald = float(stats.chi2.sf(wald, len(d)))
        weaker = bool(float(d @ b_s) < 0)
        out.append({'wald': wald, 'dof': len(d), 'p_wald': p_wald, 'level': level,
                    'weaker': weaker, 'own_p_value': float(own[k]['p_value']),
                    'weights': b_k.tolist(), 'siblings_weights': b_s.tolist(),
                    'contradicts': bool(p_wald < level and weaker
                                        and own[k]['p_value'] > alpha)})
    return out


def joint_summary(wheels: list[str], effects: list[str], extra: dict[str, dict],
                  missing: dict[str, dict], untestable: dict[str, list[str]]) -> dict:
    """Return the consistency of jointly identified wheels (module docstring).

    ``effects``: the common set (names with ``<wheel>``); ``extra[w]``: the effect wheel
    w alone would add, with its evidence; ``missing[w]``: common effects its data
    contradict, with the test; ``untestable[w]``: common effects its data cannot show.
    """
    flagged = {}
    for w in wheels:
        if w in extra or w in missing:
            flagged[w] = {'missing': canonical_order(missing.get(w, {})),
                          'extra': [extra[w]['effect']] if w in extra else [],
                          'tests': {'extra': extra.get(w), 'missing': missing.get(w, {})}}
    return {'rule': 'joint', 'reference': canonical_order(effects),
            'consistent': not flagged, 'flagged': flagged,
            'agreeing': [w for w in wheels if w not in flagged],
            'not_testable': {w: canonical_order(v) for w, v in untestable.items() if v}}
