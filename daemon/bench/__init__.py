"""Benchmarks run by ``flagtrack bench NAME``: modules defining COMMAND, HELP, add_arguments, run."""
