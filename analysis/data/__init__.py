"""Ratings in: reading an export and the exclusion rules."""
