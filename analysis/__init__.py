"""Statistics of the perceptual test: rater filtering, ANOVA, Tukey HSD, mixed models, figures."""
