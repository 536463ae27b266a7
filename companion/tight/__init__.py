"""Tightly coupled GNSS/IMU estimation with a belief per satellite: numpy on the loose filter's IMU
history, no I/O.

    from companion.tight import TightConfig, TightNavigator, RawGnss, Odometry, WEIGHTINGS
    nav = TightNavigator(TightConfig(), method="second-order", frame=None, ephemerides=store)
    nav.push(AttitudeSample(...)); nav.push(ImuSample(...)); nav.push(RawGnss(t_us, epoch))
    nav.estimate()  # NavEstimate, as companion.estimator.Navigator's

Modules: ``config`` (parameters), ``model`` (state, process, measurement models and Jacobians),
``belief`` (the per-satellite loss, gradient and second-order step), ``weighting`` (the rows by
name), ``engine`` (the filter, out-of-sequence exact), ``satcache`` (satellite states and
atmospheric delays every 5 s), ``_tight`` (C, ``_tight.c``, built by ``make venv``: the epoch's
numeric hot path), ``samples`` (RawGnss, Odometry), ``navigator`` (front end).
"""

from companion.tight.config import TightConfig
from companion.tight.navigator import TightNavigator
from companion.tight.samples import Odometry, RawGnss
from companion.tight.weighting import DEFAULT_WEIGHTING, WEIGHTINGS, check_weighting

__all__ = ["DEFAULT_WEIGHTING", "WEIGHTINGS", "Odometry", "RawGnss", "TightConfig", "TightNavigator",
           "check_weighting"]
