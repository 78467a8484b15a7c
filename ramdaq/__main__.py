"""``python -m ramdaq``: the ``ramdaq`` command."""

import sys

from ramdaq.daq.commands.cli import main

sys.exit(main())
