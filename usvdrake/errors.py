"""The one exception a user's bad input raises: :class:`ConfigError` (plain Python, no Drake)."""

from __future__ import annotations

from pathlib import Path


class ConfigError(ValueError):
    """A configuration file is wrong; the message is one line: file, key, expected, got."""

    def __init__(self, file: str | Path, key: str, expected: str, got: str):
        self.file, self.key, self.expected, self.got = str(file), key, expected, got
        where = f"key '{key}'" if key else "document"
        super().__init__(f"{file}: {where}: expected {expected}, got {got}")
