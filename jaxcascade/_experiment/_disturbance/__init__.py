"""Output disturbances of a simulated experiment and their registry.

A disturbance is a `Disturbance` (`_base.py`): an `eqx.Module` whose fields are its
settings, called as `noise(key, n, dtype)` for `n` samples of a zero-mean process of
unit variance; `_simulate.add_noise(key, y, snr, noise)` scales it to the paper's SNR.
Adding one is a module here plus one line in `NOISES` (and its name in `_names.NOISES`).
"""

from __future__ import annotations

from typing import Any

from ._arma import AR, ARMA
from ._base import Disturbance
from ._outliers import Outliers
from ._student_t import StudentT
from ._white import White

NOISES: dict[str, type[Disturbance]] = {
    cls.name: cls for cls in (White, AR, ARMA, StudentT, Outliers)
}


def disturbance(name: str, **settings: Any) -> Disturbance:
    """The disturbance registered as `name` with `settings` (lists, nested ones too,
    become tuples); a `ValueError` naming what is known when the name or a setting is
    not."""
    if name not in NOISES:
        raise ValueError(f"Unknown noise kind {name!r}; known kinds: {', '.join(NOISES)}.")
    cls = NOISES[name]
    known = [f for f in cls.__dataclass_fields__ if not f.startswith("_")]
    if name == "ar":
        known = [f for f in known if f != "zeros"]
    unknown = sorted(set(settings) - set(known))
    if unknown:
        listed = ", ".join(sorted(known)) or "none"
        raise ValueError(
            f"Unknown setting {unknown[0]!r} for noise {name!r}; known settings: {listed}."
        )

    def frozen(value):  # static settings are hashed: lists, also nested ones, as tuples
        return tuple(frozen(v) for v in value) if isinstance(value, list | tuple) else value

    plain = {k: frozen(v) for k, v in settings.items()}
    return cls(**plain)


__all__ = ["AR", "ARMA", "NOISES", "Disturbance", "Outliers", "StudentT", "White", "disturbance"]
