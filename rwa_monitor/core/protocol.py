"""The protocol every streaming detector follows (LLR, VSADC, FSS window diagnoser).

One sample in per ``update`` call, the findings of that sample out (a list of events, or
a diagnosis or None); ``reset()`` forgets everything; ``counters`` (a property) counts the
input that was dropped or held and why; ``params`` (a property) returns the checked
keyword parameters (their schema is in core/schema.py); ``last_event`` is the latest
finding. Nodes, pipelines and benchmarks rely on these names only.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class StreamingDetector(Protocol):
    """A per-sample detector: update, reset, counters, params, last_event."""

    def update(self, *args: Any, **kwargs: Any) -> Any:
        """Take one sample; return what it triggers."""

    def reset(self) -> None:
        """Forget every sample, counter and finding."""

    @property
    def counters(self) -> dict[str, int]:
        """Dropped or held input by reason."""

    @property
    def params(self) -> dict[str, Any]:
        """The checked keyword parameters."""

    @property
    def last_event(self) -> Any:
        """The latest finding, or None."""
