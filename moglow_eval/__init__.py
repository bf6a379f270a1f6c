"""moglow-eval: perceptual evaluation of generated human motion, end to end.

`moglow_eval.core` holds what every part shares (the clip format, the study's facts, CSV readers, one-line CLI
errors); `moglow_eval.console` is the console command `moglow-eval`. The parts themselves (`generation`,
`rendering`, `rating_app`, `analysis`) are top-level packages, because `python -m generation.make_stimuli` and
`python -m analysis.report` are the interface (docs/ARCHITECTURE.md).
"""
