"""The command line's faces of the library's and the paper's commands.

Each module here holds one command's options (``configure_parser``) and its entry point
(``run_from_cli``), and imports nothing heavier than the standard library and
`bayes_fdi.cli_arguments` at import time: ``bayes-fdi COMMAND --help`` and usage errors answer
without loading torch. The work is imported when the command runs. Commands whose own module
is already light keep their options beside their work (the deployment commands, the
benchmark); `bayes_fdi.cli` lists where each command lives.
"""
