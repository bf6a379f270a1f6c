"""The study's state and where it is kept: the manifest, the database, the settings and the study file, its rounds, and
the reasons a vote may carry.
"""
