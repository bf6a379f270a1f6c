"""What every part shares and nothing else: the command-line error convention (`moglow_eval.core.cli`).

`core` imports nothing from the four parts (generation, rendering, rating_app, analysis); they import it.
"""
