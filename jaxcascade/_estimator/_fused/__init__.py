"""The fused normal-equations kernel: a native XLA custom call for CPUs.

`normal_equations.cc` computes, for a batch of records, what `_regression.regression`
followed by the Gram products computes, in one pass over time and without storing the
regressor matrix (see the file's header). It is compiled on first use with the machine's
C++ compiler against the XLA FFI headers that jaxlib ships, cached on disk and registered
with `jax.ffi`; nothing is downloaded. Where no compiler is found or the build fails,
`available()` is False, `reason()` says why, and the estimator uses the XLA path.

- `JAXCASCADE_BUILD_DIR`: where compiled kernels are cached (default
  `$XDG_CACHE_HOME/jaxcascade` or `~/.cache/jaxcascade`).
- `CXX`: the compiler (default `c++`, then `g++`).
- `JAXCASCADE_FUSED=off`: never build or use the kernel.
- `JAXCASCADE_THREADS`: threads per call (default: the machine's hardware threads),
  divided among the calls running at once (a batch split over host threads).
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import pathlib
import platform
import shutil
import subprocess
import tempfile

import numpy as np

TARGET = "jaxcascade_normal_equations"
SOURCE = pathlib.Path(__file__).with_name("normal_equations.cc")
FLAGS = ("-O3", "-march=native", "-std=c++17", "-fPIC", "-shared", "-w")
MAX_COLUMNS = 64  # block-1 columns the kernel holds (kMaxColumns)
MAX_LAG = 16  # r and p (kMaxLag)


def _cache_dir() -> pathlib.Path:
    if "JAXCASCADE_BUILD_DIR" in os.environ:
        return pathlib.Path(os.environ["JAXCASCADE_BUILD_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or pathlib.Path.home() / ".cache"
    return pathlib.Path(base) / "jaxcascade"


def _compiler() -> str | None:
    for name in (os.environ.get("CXX"), "c++", "g++"):
        path = shutil.which(name) if name else None
        if path:
            return path
    return None


def _cpu_signature() -> str:
    # -march=native code must not be reused on another processor (shared home folders).
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                return line
    except OSError:
        pass
    return platform.processor() + platform.machine()


@functools.lru_cache(maxsize=1)
def _build() -> tuple[pathlib.Path | None, str]:
    """Compile (or find) the kernel; `(path, "")` or `(None, why not)`."""
    if os.environ.get("JAXCASCADE_FUSED", "").lower() in ("off", "0", "false"):
        return None, "disabled by JAXCASCADE_FUSED"
    import jax
    import jaxlib

    compiler = _compiler()
    if compiler is None:
        return None, "no C++ compiler found (set CXX)"
    include = jax.ffi.include_dir()
    identity = "\n".join(
        [SOURCE.read_text(), " ".join(FLAGS), compiler, jaxlib.__version__, _cpu_signature()]
    )
    digest = hashlib.sha256(identity.encode()).hexdigest()[:16]
    folder = _cache_dir()
    path = folder / f"normal_equations-{digest}.so"
    if path.exists():
        return path, ""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=folder) as scratch:
            target = pathlib.Path(scratch) / path.name
            done = subprocess.run(
                [compiler, *FLAGS, f"-I{include}", str(SOURCE), "-o", str(target), "-pthread"],
                capture_output=True,
                text=True,
            )
            if done.returncode != 0:
                return None, f"the kernel did not compile: {done.stderr.strip()[-500:]}"
            os.replace(target, path)  # atomic: concurrent builders agree
    except OSError as error:
        return None, f"cannot build in {folder}: {error}"
    return path, ""


@functools.lru_cache(maxsize=1)
def _register() -> str:
    path, why = _build()
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
