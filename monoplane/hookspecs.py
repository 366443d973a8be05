"""Every pluggy hook of monoplane, typed and documented.

A plugin is any module or object with functions marked ``@monoplane.hookimpl`` whose names
match the specs below. Built-in stages register through exactly these hooks (see
``monoplane.host.registry.DEFAULT_PLUGINS``); third-party packages are found through the
``monoplane`` entry-point group::

    [project.entry-points.monoplane]
    my_stages = "my_package.stages"

Registration hooks return a list of stage classes (subclasses of
:class:`monoplane.stages.base.Stage`); there is one per stage kind, generated from
:data:`monoplane.stages.base.KINDS` (``monoplane_register_samplers``, ...). Observation hooks
are called while a pipeline runs and must not change the data they see.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import pluggy

from monoplane.stages.base import KINDS, Stage, StageKind

if TYPE_CHECKING:
    from monoplane.datamodel import Reconstruction
    from monoplane.export.exporter import Exporter

PROJECT_NAME = "monoplane"

hookspec = pluggy.HookspecMarker(PROJECT_NAME)
hookimpl = pluggy.HookimplMarker(PROJECT_NAME)


def _registration_spec(kind: StageKind) -> Callable[[], list[type[Stage]]]:
    """The registration hookspec of one stage kind, named ``kind.hook``."""

    def register() -> list[type[Stage]]:
        raise NotImplementedError  # a hookspec is never called; pluggy calls the impls

    register.__name__ = register.__qualname__ = kind.hook
    register.__module__ = __name__
    register.__doc__ = (f"{kind.summary}\n\nConfig table ``[{kind.name}]``. Contract: "
                        f":class:`{kind.base.__module__}.{kind.base.__qualname__}`.")
    return hookspec(register)


# One registration hook per stage kind, generated from the kinds list so that a new kind needs
# no spec of its own here (pluggy finds hookspecs by scanning this module's attributes).
for _kind in KINDS.values():
    globals()[_kind.hook] = _registration_spec(_kind)
del _kind


@hookspec
def monoplane_register_baselines() -> dict[str, Callable[..., Reconstruction]]:
    """External plane detectors to compare against, by method name (``--baseline NAME``).

    Each value is a callable ``baseline(frame, *, seed=0, **options) -> Reconstruction`` that
    takes a cue-filled frame and returns planes in its camera frame and depth units. It may
    record ``timings["baseline.call"]``: the seconds of its core call alone (data conversion
    excluded), which ``monoplane bench`` and ``monoplane eval`` compare against.

    The keyword ``options`` override fields of the baseline's settings (``monoplane eval
    --baseline-set NAME.FIELD=VALUE``); an unknown option or an ill-typed value raises a
    one-line :class:`~monoplane.errors.ConfigError` listing the valid ones
    (:func:`monoplane.evaluation.baselines.baseline_config` does this for a settings
    dataclass). A callable that exposes that dataclass as ``config_class`` has its options
    checked before the first frame. Used by :mod:`monoplane.evaluation.baselines`; names must be
    unique across plugins.
    """


@hookspec
def monoplane_stage_finished(kind: str, name: str, seconds: float, frame_name: str) -> None:
    """Observe a stage call finishing: its kind, plugin name, wall time and the frame name.

    Used by ``monoplane bench`` for per-stage timings; plugins may log or profile with it.
    """


# --- output formats -------------------------------------------------------------------------


@hookspec
def monoplane_register_exporters() -> list[Exporter]:
    """Output formats: what :func:`monoplane.export.save` (and so ``monoplane run``, ``batch``,
    ``cloud`` and ``multiview``) can write into a result's folder.

    Return a list of :class:`monoplane.plugin.Exporter`, one per format, each stating:

    * ``name``: unique across plugins, lower-case words joined by ``-``; ``monoplane plugins``
      lists it and ``save(..., formats=[...])`` selects by it;
    * ``files``: per result kind it applies to (``"frame"``: a
      :class:`~monoplane.datamodel.Reconstruction`; ``"cloud"``: a
      :class:`~monoplane.datamodel.CloudResult`; ``"multiview"``: a
      :class:`~monoplane.multiview.MultiviewResult`), the paths it writes, relative to the
      folder. ``monoplane batch`` derives its completeness check from the ``"frame"`` files of
      the formats on by default, so they must be exactly what ``write`` writes;
    * ``write(result, folder, shared)``: writes those files into ``folder``, an existing
      temporary folder that becomes the output only when every format has succeeded (raise to
      abandon it). It tells result kinds apart by ``result.result_kind``, never by type.
      ``shared`` (:class:`monoplane.export.shared.SharedWork`) hands out what several formats
      need, e.g. ``shared.mesh(result)``, the plane meshes, computed once. The views of a
      multi-view result are written with the ``"frame"`` formats into their own folders
      (``view_000``, ...) before the ``"multiview"`` formats run;
    * ``default``: written unless the caller names the formats it wants;
    * ``summary``: one line for ``monoplane plugins``.

    The built-in formats (``labels``, ``ply``, ``gltf``, ``depth``, ``config``, ``rerun``) are
    modules of :mod:`monoplane.export` registered through this hook, as a third-party package's
    are through the ``monoplane`` entry-point group. A malformed statement or a name registered
    twice raises :class:`~monoplane.errors.PluginError` naming the plugin.
    """
