"""The parallel (MUSHRA-like) design: its plug-in (design) and its statistics."""
