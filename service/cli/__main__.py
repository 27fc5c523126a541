"""``python -m service.cli``: the ``vtrack`` command."""

import sys

from service.cli import main

sys.exit(main())
