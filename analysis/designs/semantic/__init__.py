"""The semantic design (GENEA 2026's semantic alignment): its plug-in (design); its statistics are the appropriateness
design's MAS."""
