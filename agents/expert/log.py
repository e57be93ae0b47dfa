"""The expert's failure log: why plans failed and what it did instead, one line per event, capped per episode."""

from __future__ import annotations

MAX_FAILURE_LOG = 1000
"""At most this many entries are kept in :attr:`FailureLog.entries` per episode (then a count)."""


class FailureLog:
    """What went wrong in an episode and what the expert did about it (``ExpertPolicy.failure_log``)."""

    def __init__(self) -> None:
        self.entries: list[str] = []
        """the messages, oldest first (at most :data:`MAX_FAILURE_LOG`)."""
        self.dropped = 0
        """messages not kept because the log was full."""

    def add(self, message: str) -> None:
        """Append ``message`` (counted in :attr:`dropped` instead once the log holds ``MAX_FAILURE_LOG``)."""
        if len(self.entries) < MAX_FAILURE_LOG:
            self.entries.append(message)
        else:
            self.dropped += 1

    def clear(self) -> None:
        """Start a new episode's log."""
        self.entries.clear()
        self.dropped = 0
