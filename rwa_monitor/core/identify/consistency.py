"""Consistency of the effects identified on sibling wheels of one file.

Identical wheels on one bus should need the same named effects. The majority set of
effect names (ties: the set of the first wheel among them) is the reference; a wheel
whose set differs is flagged with what it lacks and what it adds. Parameter values are
shown side by side, not compared: they may differ legitimately (wear, temperature).
"""

from __future__ import annotations

from collections import Counter


def compare_effects(effects: dict[str, list[str]]) -> dict:
    """Return the reference effect set and the wheels that differ from it.

    ``effects`` maps wheel id -> names of its identified effects (in the order added).
    """
    if not effects:
        return {'reference': [], 'consistent': True, 'flagged': {}}
    sets = {w: frozenset(names) for w, names in effects.items()}
    counts = Counter(sets.values())
    top = max(counts.values())
    reference = next(s for s in sets.values() if counts[s] == top)
    flagged = {w: {'missing': sorted(reference - s), 'extra': sorted(s - reference)}
               for w, s in sets.items() if s != reference}
    return {'reference': sorted(reference), 'consistent': not flagged, 'flagged': flagged,
            'agreeing': sorted(w for w, s in sets.items() if s == reference)}
