"""The paper's two examples (Vörös 2016, section 4)."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from ._model import CascadeParams, Orders


@dataclasses.dataclass(frozen=True)
class Example:
    """A paper example: true parameters and the identification experiment. `number`: 1
    or 2, or the name of a general-backlash example (`_general_backlash.GeneralExample.
    example`)."""

    number: int | str
    values: dict
    n_samples: int
    snr: float = 25.0
    amplitude: float = 2.0
    orders: Orders = Orders(2, 2, 2, 2)

    def params(self, dtype=None) -> CascadeParams:
        return CascadeParams.from_dict(self.values, self.orders).astype(
            dtype or jnp.result_type(float)
        )


# b from x(t) = v(t-1) + 0.15 v(t-2) + 0.2 x(t-1) - 0.35 x(t-2), i.e. b1 = -0.2, b2 = 0.35.
_LINEAR = {"a2": 0.15, "b1": -0.2, "b2": 0.35}

EXAMPLES = {
    1: Example(
        1,
        {
            "MR1": 1.2,
            "MR2": -1.4,
            "DR1": 1.0,
            "ML1": 0.7,
            "ML2": -0.8,
            "DL1": -0.9,
            **_LINEAR,
            "cL": 0.2,
            "mR": 1.2,
            "cR": 0.3,
        },
        n_samples=4000,
    ),
    2: Example(
        2,
        {
            "MR1": 0.4,
            "MR2": 1.0,
            "DR1": 0.5,
            "ML1": -0.1,
            "ML2": -0.8,
            "DL1": -0.6,
            **_LINEAR,
            "cL": 0.35,
            "mR": 1.0,
            "cR": 0.7,
        },
        n_samples=2000,
    ),
}


def example(number: int) -> Example:
    """Paper example 1 or 2."""
    if number not in EXAMPLES:
        raise ValueError(f"Unknown example {number!r}; the paper has examples 1 and 2.")
    return EXAMPLES[number]
