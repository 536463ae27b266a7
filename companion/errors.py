"""Errors a user can cause (bad config, bad log, port in use): shown as one line, no traceback."""

from __future__ import annotations

import difflib
from collections.abc import Sequence


class UserError(Exception):
    """Base class: the CLI prints ``beliefnav: error: <message>`` and exits with status 2."""


class ConfigError(UserError, ValueError):
    """A user-caused configuration error; its message is one line naming file and field."""


def not_one_of(what: str, value: str, valid: Sequence[str]) -> ConfigError:
    """``--method 'secnd': not one of naive, ... (did you mean 'second-order'?)``: the one form of a
    mistyped name (``what`` says where it came from: an option, a file and field)."""
    near = difflib.get_close_matches(value, valid, n=1, cutoff=0.5)
    hint = f" (did you mean {near[0]!r}?)" if near else ""
    return ConfigError(f"{what} {value!r}: not one of {', '.join(valid)}{hint}")
