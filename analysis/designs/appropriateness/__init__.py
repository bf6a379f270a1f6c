"""The appropriateness design: its plug-in (design) and the MAS."""
