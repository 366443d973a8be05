"""The base of every stage: :class:`Stage`, and :func:`param` for the fields of its ``Config``.

The contracts of the stage kinds subclass it (:mod:`monoplane.contracts.frame_stages`,
:mod:`monoplane.contracts.scene_stages`); :mod:`monoplane.contracts` gathers them all.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

from monoplane.errors import StageError

T = TypeVar("T")


def param(default: Any, doc: str, **kwargs: Any) -> Any:
    """A config field with a default and a one-line description shown by ``monoplane plugins``.

    Mutable defaults (lists) are copied per instance.
    """
    if isinstance(default, (list, dict)):
        return field(default_factory=lambda: type(default)(default), metadata={"doc": doc},
                     **kwargs)
    return field(default=default, metadata={"doc": doc}, **kwargs)


def config_key(f: dataclasses.Field) -> str:
    """User-facing key of a config field: a Python keyword is spelled with a trailing
    underscore in the dataclass (``lambda_``) and without it in configs (``lambda``)."""
    return f.name[:-1] if f.name.endswith("_") else f.name


@dataclass
class NoConfig:
    """A stage without parameters."""


class Stage:
    """Base of every stage. Subclasses set ``kind``, ``name`` and usually ``Config``."""

    kind: ClassVar[str] = ""
    name: ClassVar[str] = ""
    Config: ClassVar[type] = NoConfig

    def __init__(self, config: Any | None = None) -> None:
        self.config = self.Config() if config is None else config

    @classmethod
    def parameters(cls) -> list[tuple[str, str, Any, str]]:
        """``(key, type, default, doc)`` for each config field, for listings and docs.

        ``key`` is what a config or ``--set`` names (see :func:`config_key`).
        """
        rows = []
        for f in dataclasses.fields(cls.Config):
            if f.default is not dataclasses.MISSING:
                default = f.default
            elif f.default_factory is not dataclasses.MISSING:
                default = f.default_factory()
            else:
                default = None
            type_name = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")
            rows.append((config_key(f), type_name, default, f.metadata.get("doc", "")))
        return rows


def run_stage(kind: str, name: str, fn: Callable[..., T], *args: Any) -> T:
    """``fn(*args)``, a failure reported as a :class:`~monoplane.errors.StageError` naming the
    stage kind and plugin: the one place where stage failures are wrapped.

    A :class:`StageError` raised inside passes through unchanged, so the innermost stage is
    the one named (a failing sampler, not the RANSAC that called it).
    """
    try:
        return fn(*args)
    except StageError:
        raise
    except Exception as exc:
        raise StageError(kind, name, exc) from exc
