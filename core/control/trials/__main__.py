"""``python -m core.control.trials``."""

import sys

from core.control.trials import main

if __name__ == "__main__":
    sys.exit(main())
