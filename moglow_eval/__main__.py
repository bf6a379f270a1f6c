"""python -m moglow_eval COMMAND [ARGS] (see moglow_eval)."""

import sys

from . import main

if __name__ == "__main__":
    sys.exit(main())
