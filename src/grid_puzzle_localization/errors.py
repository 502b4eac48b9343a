"""Errors a user can cause. Their message names the input and says what to do."""


class UserError(Exception):
    """Bad input or parameters: the CLI prints it as one line and exits with status 2."""


class PcdError(UserError):
    """A PCD file that cannot be read as declared (missing, truncated, corrupt, unsupported)."""
