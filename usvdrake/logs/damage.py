"""What a log reader left out of a damaged file: :class:`ReadDamage`.

The readers (mission logs, CARMEN logs, ROS bags) skip what they cannot read — a record whose
framing or content is corrupt, a line cut short, a compressed stream that breaks off — and
note it here instead of raising, so a run on a damaged log goes on with what is left and says
how much that was. Each skip is keyed by where it is in its file (a byte offset, a line
number), so reading the same file twice (a summary pass, then the messages) counts it once.
"""

from collections import Counter
from dataclasses import dataclass, field


@dataclass
class ReadDamage:
    """Skipped records by where they are: ``{(file, where): (reason, unread bytes)}``."""

    skips: dict = field(default_factory=dict)

    def skip(self, file, where, reason: str, unread_bytes: int = 0) -> None:
        """Note that the record at ``where`` in ``file`` was left out, and why."""
        self.skips.setdefault((str(file), where), (reason, int(unread_bytes)))

    @property
    def records(self) -> int:
        return len(self.skips)

    @property
    def unread_bytes(self) -> int:
        return sum(n for _, n in self.skips.values())

    def reasons(self) -> dict[str, int]:
        """{reason: records skipped for it}, the most frequent first."""
        return dict(Counter(r for r, _ in self.skips.values()).most_common())

    def metrics(self) -> dict:
        """``skipped_records``, ``unread_bytes`` and ``skip_reasons`` for a run's metrics."""
        return {
            "skipped_records": self.records,
            "unread_bytes": self.unread_bytes,
            "skip_reasons": self.reasons(),
        }

    def note(self) -> str:
        """`` (N damaged records skipped)`` for an error message, or "" when nothing was."""
        if not self.records:
            return ""
        return f" ({self.records} damaged or unreadable records skipped)"


def count_into(damage: ReadDamage | None) -> ReadDamage:
    """``damage``, or a fresh :class:`ReadDamage` for a caller that does not ask for one."""
    return ReadDamage() if damage is None else damage
