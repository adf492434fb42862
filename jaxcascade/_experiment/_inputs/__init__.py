"""Input designs of a simulated experiment and their registry.

A design is an `InputDesign` (`_base.py`): an `eqx.Module` whose static fields are its
settings, called as `design(key, n, dtype)` for one input record. The kinds: `uniform`
(the paper's), `gaussian`, `multisine`, `multilevel` and `file` (segments of a measured
record). Adding one is a module here plus one line in `INPUTS` (and its name in
`_names.INPUTS`).
"""

from __future__ import annotations

from typing import Any

from ._base import DEFAULT_RMS, InputDesign
from ._file import File
from ._gaussian import Gaussian
from ._multilevel import Multilevel
from ._multisine import Multisine
from ._uniform import Uniform

INPUTS: dict[str, type[InputDesign]] = {
    cls.name: cls for cls in (Uniform, Gaussian, Multisine, Multilevel, File)
}
# settings a kind accepts beyond its fields
_SYNONYMS = {"gaussian": {"rms": "std"}}
_INTERNAL = ("sha256", "record")


def known_settings(name: str) -> list[str]:
    fields = [f for f in INPUTS[name].__dataclass_fields__ if f not in _INTERNAL]
    return sorted({*fields, *_SYNONYMS.get(name, {})})


def input_design(name: str, **settings: Any) -> InputDesign:
    """The input design registered as `name` with `settings` (lists become tuples); a
    `ValueError` naming what is known when the name or a setting is not."""
    if name not in INPUTS:
        raise ValueError(f"Unknown input kind {name!r}; known kinds: {', '.join(INPUTS)}.")
    known = known_settings(name)
    unknown = sorted(set(settings) - set(known))
    if unknown:
        raise ValueError(
            f"Unknown setting {unknown[0]!r} for input {name!r}; known settings: "
            f"{', '.join(known)}."
        )
    plain = {}
    for key, value in settings.items():
        key = _SYNONYMS.get(name, {}).get(key, key)
        if key in plain:
            raise ValueError(f"Input {name}: give {key} once (rms is its synonym).")
        plain[key] = tuple(value) if isinstance(value, list) else value
    return INPUTS[name](**plain)


__all__ = [
    "DEFAULT_RMS",
    "INPUTS",
    "File",
    "Gaussian",
    "InputDesign",
    "Multilevel",
    "Multisine",
    "Uniform",
    "input_design",
]
