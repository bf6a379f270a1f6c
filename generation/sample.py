"""Moved to `generation.sampling.sample` (moglow_eval.core.moved)."""

from moglow_eval.core import moved

moved.point(__spec__.name, __name__)
