"""python -m moglow_eval COMMAND [ARGS] (see moglow_eval.console)."""

import sys

from .console import main

if __name__ == "__main__":
    sys.exit(main())
