"""A candidate effect of the selection: its name, kind, grid and Bonferroni count."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class Candidate:
    """An effect to test: its vocabulary name, kind and grid of nonlinear parameters."""

    name: str
    kind: str
    grid: list[dict]
    tests: int = 0
    skipped: str | None = None
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.tests:
            self.tests = len(self.grid)

    def renamed(self, name: str) -> 'Candidate':
        """Return a copy under another name (a repeat of an effect that may recur)."""
        return Candidate(name, self.kind, self.grid, self.tests, self.skipped,
                         dict(self.extra))
