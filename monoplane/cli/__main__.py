"""``python -m monoplane.cli``: same as the ``monoplane`` script."""

import sys

from monoplane.cli import main

sys.exit(main())
