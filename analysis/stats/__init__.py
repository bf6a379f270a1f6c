"""Statistics as pure functions on DataFrames: ANOVA and Tukey HSD, bootstrap, mixed and ordinal models, agreement, the
style factor, the power of a planned study.
"""
