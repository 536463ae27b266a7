"""Output directories: checked before any work starts, one line when they cannot be used."""

from __future__ import annotations

import os
from pathlib import Path

from companion.errors import UserError


def check_out_dir(path: str | os.PathLike[str], option: str = "--out") -> Path:
    """UserError if ``path`` names something that is not a directory (nothing is created)."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise UserError(f"{option} {p}: exists and is not a directory")
    return p


def ensure_out_dir(path: str | os.PathLike[str], option: str = "--out") -> Path:
    """Create ``path`` (and parents) as a directory; UserError if it names a file or cannot be made."""
    p = check_out_dir(path, option)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{option} {p}: cannot create the directory: {exc.strerror or exc}") from None
    if not os.access(p, os.W_OK | os.X_OK):
        raise UserError(f"{option} {p}: not writable")
    return p
