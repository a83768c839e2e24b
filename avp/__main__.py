"""``python -m avp demo`` is ``avp demo``."""

import sys

from .cli import main

sys.exit(main())
