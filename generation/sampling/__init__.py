"""Sampling trained models, and the shipped models with their quality guard."""
