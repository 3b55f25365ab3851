"""``python -m chewbot``: the same program as ``chewbot``."""

import sys

from chewbot.command import main

sys.exit(main())
