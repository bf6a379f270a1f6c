"""A study of your own motion: the study file, the builder from folders, and the demo study with speech."""
