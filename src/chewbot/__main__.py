"""``python -m chewbot``: the same program as ``chewbot``."""

import sys

from chewbot.commands.common import main

sys.exit(main())
