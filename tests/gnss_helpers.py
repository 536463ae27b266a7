"""The synthetic constellation of ``gcs_tools.gnss.synthetic`` under the names the tests use."""

from gcs_tools.gnss.synthetic import (  # noqa: F401
    BASE,
    CLOCKS_M,
    KLOBUCHAR,
    RX_ECEF,
    T0,
    TOE_SOW,
    WEEK,
    constellation,
    observe,
    store,
)
