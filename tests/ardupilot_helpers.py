"""ArduCopter SITL for tests: the binary from ``<repo>/../shared/tools/ardupilot/`` (or
$BELIEFNAV_ARDUPILOT_BIN). Missing, the tests skip on a developer machine and FAIL in CI
(environment CI=true), where the shared directory is always checked out beside the repo."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from companion.errors import UserError
from gcs_tools.ardupilot.sitl import resolve_binary


def require_ardupilot() -> Path:
    try:
        return resolve_binary()
    except UserError as exc:
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"ArduPilot SITL is required in CI: {exc}")
        pytest.skip(str(exc))
