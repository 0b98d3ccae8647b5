"""User-facing errors: the CLI prints them as one line (exit status 2), never a traceback."""


class DeriveError(ValueError):
    """Bad input or an impossible request, explained in one line."""


class NotGenerated(DeriveError, AttributeError):
    """A function of the robot's usual set that generation left out (forward dynamics and the ODE where
    M(q) is singular), asked for by name: one line naming why. An AttributeError too, so ``hasattr``
    and ``getattr(module, name, default)`` answer as for any missing attribute."""
