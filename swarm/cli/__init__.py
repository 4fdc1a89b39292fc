"""The `swarm` command line (`main`), one module per command group; options shared by several
groups are in `options`, errors become one line and an exit code in `errors`."""

from swarm.cli.main import main

__all__ = ["main"]
