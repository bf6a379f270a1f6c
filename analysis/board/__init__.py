"""The board: a static site of the results of one or more reports, for a challenge (published once) or a leaderboard
(a release per build). `python -m analysis.board` (command), over `tasks` (the reports, their exports and stimuli,
read and checked), `clips` (which videos each system shows), `pages` (the HTML), `release` (one release's files) and
`folder` (the board's folder and its atomic writes)."""

from .command import build_board, build_parser, main
from .tasks import TaskSpec

__all__ = ["TaskSpec", "build_board", "build_parser", "main"]
