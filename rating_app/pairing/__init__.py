"""Which clips a rater gets: the balanced assignment, and active pairing with its stopping rule."""
