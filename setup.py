"""Build of the estimators' C cores (companion/estimator/_core.c, companion/tight/_tight.c); everything else
is in pyproject.toml.

It uses numpy's C API (numpy is a build requirement). -ffp-contract=off: no fused multiply-add,
so the core computes the same bits as the float expressions it replaced (docs/estimator.md, Speed)."""

import numpy
from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "companion.estimator._core",
            ["companion/estimator/_core.c"],
            depends=["companion/estimator/held.h"],
            include_dirs=[numpy.get_include()],
            extra_compile_args=["-O2", "-ffp-contract=off", "-fno-fast-math", "-Wall"],
        ),
        Extension(  # the tightly coupled filter's hot path (companion/tight/_tight.c)
            "companion.tight._tight",
            ["companion/tight/_tight.c"],
            depends=["companion/estimator/held.h"],  # the held-time noise, shared with _core.c
            include_dirs=[numpy.get_include()],
            # -fvect-cost-model=cheap: its elementwise loops vectorised (no reassociation: the same bits)
            extra_compile_args=["-O2", "-fvect-cost-model=cheap", "-ffp-contract=off", "-fno-fast-math",
                                "-Wall"],
        ),
    ]
)
