"""The ``orbitdata`` command line (typer). Commands build configs and call the library."""
