"""Tests compute in float64: the oracle comparisons need it (the package never sets it)."""

import jax

jax.config.update("jax_enable_x64", True)
