"""Exception types that map to the command's exit codes."""


class ParsphError(Exception):
    """A failure of the run that is not the user's input (exit code 1)."""

    exit_code = 1


class InputError(ParsphError):
    """Bad input: scene file, command-line option, output directory (exit code 2)."""

    exit_code = 2
