"""``python -m suspid``: the command line."""

from suspid.cli import main

main()
