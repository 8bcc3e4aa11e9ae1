"""``python -m core.planning.reachability``."""

import sys

from core.planning.reachability import main

if __name__ == "__main__":
    sys.exit(main())
