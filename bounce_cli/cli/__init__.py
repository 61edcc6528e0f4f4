"""The command line: the typer app (``commands``) and the console script's entry point."""
