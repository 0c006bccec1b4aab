"""The ``orbitmodel`` command line: typer commands that build configs and call the library."""
