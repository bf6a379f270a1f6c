"""The dyadic design (GENEA 2023's interlocutor appropriateness): its plug-in (design); its statistics are the
appropriateness design's MAS."""
