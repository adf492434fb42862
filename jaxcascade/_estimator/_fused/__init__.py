"""The fused normal-equations kernel: a native XLA custom call for CPUs.

`normal_equations.cc` computes, for a batch of records, what `_regression.regression`
followed by the Gram products computes, in one pass over time and without storing the
regressor matrix (see the file's header). It is compiled on first use with the machine's
C++ compiler against the XLA FFI headers that jaxlib ships and cached on disk
(`jaxcascade._native`, which says where and how), and registered here with `jax.ffi`;
nothing is downloaded. Where no compiler is found or the build fails, `available()` is
False, `reason()` says why, and the estimator uses the XLA path.

- `JAXCASCADE_FUSED=off`: never build or use the kernel (`_native`: the build's other
  settings, `JAXCASCADE_BUILD_DIR` and `CXX`).
- `JAXCASCADE_THREADS`: threads per call (default: the machine's hardware threads),
  divided among the calls running at once (a batch split over host threads).
"""

from __future__ import annotations

import ctypes
import functools

import numpy as np

from ..._native import build

TARGET = "jaxcascade_normal_equations"
MAX_COLUMNS = 64  # block-1 columns the kernel holds (kMaxColumns)
MAX_LAG = 16  # r and p (kMaxLag)


@functools.lru_cache(maxsize=1)
def _register() -> str:
    path, why = build()
    if path is None:
        return why
    import jax

    try:
        library = ctypes.cdll.LoadLibrary(str(path))
        capsule = jax.ffi.pycapsule(library.JaxcascadeNormalEquations)
        jax.ffi.register_ffi_target(TARGET, capsule, platform="cpu")
    except (OSError, AttributeError, ValueError) as error:
        return f"cannot load {path}: {error}"
    return ""


def available() -> bool:
    """Whether the kernel is built and registered (builds it on first call)."""
    return _register() == ""


def reason() -> str:
    """Why the kernel is not available ("" when it is)."""
    return _register()


def supports(orders, dtype) -> bool:
    """Whether the kernel computes these orders and dtype on the default device."""
    import jax

    return (
        np.dtype(dtype) == np.float64
        and jax.default_backend() == "cpu"
        and orders.size - 2 <= MAX_COLUMNS
        and orders.r <= MAX_LAG
        and orders.p <= MAX_LAG
        and available()
    )
