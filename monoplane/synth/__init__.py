"""Synthetic indoor scenes with exact plane ground truth and monocular-style corrupted cues.

>>> from monoplane.synth import generate
>>> scene = generate(seed=0, level="mild")          # doctest: +SKIP
>>> view = scene.views[0]
>>> view.frame.depth.shape, view.gt_params.shape    # doctest: +SKIP

See :mod:`monoplane.synth.generator` for the ground-truth rules, :mod:`monoplane.synth.corrupt`
for the corruption levels and :mod:`monoplane.synth.samples` for the on-disk samples.
"""

from monoplane.synth.generator import LEVELS, MIN_PLANE_FRACTION, SynthScene, SynthView, generate
from monoplane.synth.writer import write_sample

__all__ = ["LEVELS", "MIN_PLANE_FRACTION", "SynthScene", "SynthView", "generate", "write_sample"]
