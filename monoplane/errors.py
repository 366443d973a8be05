"""Exceptions that the CLI turns into one-line messages.

Every error a user can cause (a bad file, a typo in a config key, a stage that fails on their
data) is a :class:`MonoplaneError`. Anything else reaching the CLI is a bug in monoplane.
"""

from __future__ import annotations

from collections.abc import Iterable


class MonoplaneError(Exception):
    """Base class of every user-facing monoplane error."""


class InvalidInput(MonoplaneError, ValueError):
    """Input data (arrays, files, arguments) that cannot be used as given."""


class ConfigError(MonoplaneError, ValueError):
    """A malformed config: unknown key, plugin or preset, or a value of the wrong type."""


def check_config(checks: Iterable[tuple[bool, str]], prefix: str = "") -> None:
    """Raise :class:`ConfigError` for the first check that fails.

    Config dataclasses list their checks as ``(condition, message)`` pairs in
    ``__post_init__`` and hand them here, so that each states its rules as a table.

    Parameters
    ----------
    checks : iterable of (bool, str)
        Each condition that must hold, with the message saying what it asks for.
    prefix : str, optional
        Put before the message (e.g. ``"refiner."``, when the table is not named elsewhere).

    Raises
    ------
    ConfigError
        ``prefix + message`` of the first condition that is false.
    """
    for ok, message in checks:
        if not ok:
            raise ConfigError(prefix + message)


class PluginError(MonoplaneError):
    """A plugin that cannot be loaded or registered."""


class StageError(MonoplaneError):
    """A stage raised while running; names the stage kind and plugin.

    Parameters
    ----------
    kind : str
        Stage kind, e.g. ``"labeler"``.
    name : str
        Plugin name of the stage, e.g. ``"proximity-graph-cut"``.
    cause : BaseException
        The original exception, kept as ``__cause__`` too.
    """

    def __init__(self, kind: str, name: str, cause: BaseException) -> None:
        self.kind = kind
        self.name = name
        self.cause = cause
        detail = str(cause) or type(cause).__name__
        super().__init__(f"{kind} stage '{name}' failed: {detail}")
