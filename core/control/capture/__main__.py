"""``python -m core.control.capture``."""

import sys

from core.control.capture import main

if __name__ == "__main__":
    sys.exit(main())
