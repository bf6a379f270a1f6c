"""A rater's session: its start, the trial served, its videos and the answers taken."""
