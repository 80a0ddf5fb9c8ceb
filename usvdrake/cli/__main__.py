"""``python -m usvdrake.cli ...``: the ``usvdrake`` command."""

import sys

from usvdrake.cli import main

sys.exit(main())
