"""The one exception type for mistakes a user can fix.

The command line prints a :class:`UserError` as a single ``femstudy: error: ...`` line and
exits with status 2; anything else is a bug and keeps its traceback.
"""


class UserError(Exception):
    """A bad input (file, option, value) explained in one sentence."""


def require(condition: bool, message: str) -> None:
    """Raise :class:`UserError` with ``message`` unless ``condition`` holds."""
    if not condition:
        raise UserError(message)
