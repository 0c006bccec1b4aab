"""``python -m orbitdata`` runs the command line."""

from orbitdata.cli.app import main

main()
