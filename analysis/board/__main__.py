"""`python -m analysis.board ...` runs analysis.board.command."""

import sys

from .command import main

sys.exit(main())
