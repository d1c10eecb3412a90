"""Tests of the command line (bayesmachine/cli.py, cliargs.py, host/cli): options and errors."""
