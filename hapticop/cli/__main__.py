"""`python -m hapticop.cli`: the same as the `hapticop` command."""

from hapticop.cli.main import main

main()
