"""Stick-figure rendering of motion clips to MP4 videos and PNG contact sheets."""
