"""Building the package's native kernel: `_estimator/_fused/normal_equations.cc`, compiled
with the machine's C++ compiler against the XLA FFI headers that jaxlib ships, cached on
disk (`_estimator._fused` registers and uses it).

Apart so that a command can start the build before it imports the estimators: this
module imports neither JAX nor the estimators (jaxlib's package alone, for its headers
and version), and `build_in_background` runs the compiler in its own process on another
core while the command imports, reads its records and prepares (about 3 s on the first
run on a machine; a look-up of the cached file afterwards).

- `JAXCASCADE_BUILD_DIR`: where compiled kernels are cached (default
  `$XDG_CACHE_HOME/jaxcascade` or `~/.cache/jaxcascade`).
- `CXX`: the compiler (default `c++`, then `g++`).
- `JAXCASCADE_FUSED=off`: never build it.
"""

from __future__ import annotations

import functools
import hashlib
import os
import pathlib
import platform
import shutil
import subprocess
import tempfile
import threading

SOURCE = pathlib.Path(__file__).parent / "_estimator" / "_fused" / "normal_equations.cc"
FLAGS = ("-O3", "-march=native", "-std=c++17", "-fPIC", "-shared", "-w")


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


def _jaxlib() -> tuple[str, str]:
    """`(jaxlib's header folder, its version)`, as `jax.ffi.include_dir()` finds the
    folder, without importing JAX."""
    import jaxlib
    import jaxlib.version

    folder = jaxlib.__file__ and os.path.dirname(os.path.abspath(jaxlib.__file__))
    if not folder:  # a namespace package: its first path entry
        folder = list(jaxlib.__path__)[0]
    return os.path.join(folder, "include"), jaxlib.version.__version__


# One build at a time in a process: a caller that asks while `build_in_background`'s
# thread builds waits for it, then finds the kernel built.
_BUILDING = threading.Lock()


@functools.lru_cache(maxsize=1)
def build() -> tuple[pathlib.Path | None, str]:
    """Compile (or find) the kernel; `(path, "")` or `(None, why not)`."""
    with _BUILDING:
        return _build()


def build_in_background() -> None:
    """Start `build` in a thread (module docstring). Not a daemon: a command that stops
    early waits for the build rather than leave a compiler writing into the cache."""
    threading.Thread(target=build, name="jaxcascade-kernel-build").start()


def _build() -> tuple[pathlib.Path | None, str]:
    if os.environ.get("JAXCASCADE_FUSED", "").lower() in ("off", "0", "false"):
        return None, "disabled by JAXCASCADE_FUSED"
    compiler = _compiler()
    if compiler is None:
        return None, "no C++ compiler found (set CXX)"
    include, version = _jaxlib()
    identity = "\n".join([SOURCE.read_text(), " ".join(FLAGS), compiler, version, _cpu_signature()])
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
