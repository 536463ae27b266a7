"""Errors a user can cause (bad config, bad log, port in use): shown as one line, no traceback."""


class UserError(Exception):
    """Base class: the CLI prints ``beliefnav: error: <message>`` and exits with status 2."""
