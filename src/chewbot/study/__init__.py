"""Studies that reproduce a paper's findings: each is ``run(out, force=False, progress=SILENT) -> Path``
(:class:`chewbot.progress.Progress`)."""

from chewbot.study.seed000 import run as seed000
from chewbot.study.seed001 import run as seed001

STUDIES = {"seed000": seed000, "seed001": seed001}

__all__ = ["STUDIES"]
