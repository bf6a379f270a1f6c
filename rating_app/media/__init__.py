"""The stimulus videos served blind, the bytes each session was sent, and the sound check."""
