"""Exceptions that the CLI turns into one-line messages.

Every error a user can cause (a bad file, a typo in a config key, a stage that fails on their
data) is a :class:`MonoplaneError`. Anything else reaching the CLI is a bug in monoplane.
"""

from __future__ import annotations


class MonoplaneError(Exception):
    """Base class of every user-facing monoplane error."""


class InvalidInput(MonoplaneError, ValueError):
    """Input data (arrays, files, arguments) that cannot be used as given."""


class ConfigError(MonoplaneError, ValueError):
    """A malformed config: unknown key, plugin or preset, or a value of the wrong type."""


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
