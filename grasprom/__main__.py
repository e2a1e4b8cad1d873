"""Allow ``python -m grasprom``."""

import sys

from grasprom.cli import main

if __name__ == "__main__":
    sys.exit(main())
