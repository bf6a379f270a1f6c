"""`python -m analysis ratings.csv ...` is the same as `python -m analysis.report ratings.csv ...`."""

import sys

from .report import main

sys.exit(main())
