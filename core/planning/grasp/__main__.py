"""``python -m core.planning.grasp``."""

import sys

from core.planning.grasp import main

if __name__ == "__main__":
    sys.exit(main())
