"""``python -m winder.cli``: the ``winder`` command."""

import sys

from winder.cli.commands import main

sys.exit(main())
