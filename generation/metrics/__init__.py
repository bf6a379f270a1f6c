"""Measuring motion without raters: objective per-clip metrics, the FMD's motion encoder, and the classifier
two-sample test."""
