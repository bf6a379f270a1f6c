"""The pairwise design: its plug-in (design), the preference statistics and Bradley-Terry fit, the ranking (Elo, rank
intervals, groups), reasons and rounds.
"""
