"""User-facing errors: the CLI prints them as one line (exit status 2), never a traceback."""


class DeriveError(ValueError):
    """Bad input or an impossible request, explained in one line."""
