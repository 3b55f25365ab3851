"""``chewbot cache``: where the compiled kernels are kept, and emptying it."""

from __future__ import annotations

import typer

from chewbot.commands.common import EXIT_OUTPUT, fail, stdout
from chewbot.errors import ChewbotError

cache_app = typer.Typer(no_args_is_help=False,
                        add_completion=False, pretty_exceptions_enable=False)


@cache_app.callback(invoke_without_command=True)
def cache(context: typer.Context) -> None:
    """Print the kernel cache's location, its number of libraries and their size; `chewbot cache clear` empties it.

    The cache is $CHEWBOT_CACHE, else $XDG_CACHE_HOME/chewbot, else ~/.cache/chewbot; its size is capped at
    $CHEWBOT_CACHE_MAX_MB megabytes (default 200), the least recently used libraries removed first.

    Examples:

      chewbot cache

      chewbot cache clear
    """
    if context.invoked_subcommand is not None:
        return
    from chewbot.compiled.cache import KERNELS

    try:
        info = KERNELS.info()
    except (OSError, ValueError) as exc:
        fail(ChewbotError(f"the kernel cache cannot be read: {exc}"), EXIT_OUTPUT)
    stdout.print(f"location: {info['location']}\nlibraries: {info['libraries']}\n"
                 f"size: {info['bytes'] / 1e6:.1f} MB (cap {info['max_bytes'] / 1e6:.0f} MB)", highlight=False, markup=False)


@cache_app.command("clear")
def cache_clear() -> None:
    """Remove chewbot's compiled kernels from the cache (nothing else in the folder); they are compiled again when
    next needed.

    Example:

      chewbot cache clear
    """
    from chewbot.compiled.cache import KERNELS

    try:
        count, size = KERNELS.clear()
    except OSError as exc:
        fail(ChewbotError(f"{KERNELS.root()}: cannot clear the kernel cache ({exc.strerror or exc})"), EXIT_OUTPUT)
    stdout.print(f"removed {count} libraries ({size / 1e6:.1f} MB) from {KERNELS.root()}", highlight=False, markup=False)
