"""pytest plugin of `benchmarks/mutation_check.py`: deletes one body of the package at run
time, named by the environment variable `JAXCASCADE_MUTATION` (nothing without it).

- `effect:NAME`: the effect's `input`, `output`, `parallel`, their `*_with_state` forms
  and `backlash` (its own or inherited from another effect) replaced on its class by
  `Effect`'s, which change nothing: the effect is there, with its parameters, and does
  nothing.
- `starts:NAME`: a structural effect's `starts` return none (it is never tried).
- `contacts`: `backlash_friction_contacts` with `backlash_friction`'s rotor starts (its
  only difference from it).
- `noise`: the AR noise model's fit returns white noise.
- `pem`: pem's Levenberg-Marquardt iteration returns its start, `converged`.
- `robust`: robust's multi-start returns the adaptive step's estimate.
"""

from __future__ import annotations

import os


def pytest_configure(config):
    mutation = os.environ.get("JAXCASCADE_MUTATION", "")
    if mutation:
        apply(mutation)


def apply(mutation: str) -> None:
    from jaxcascade._measured._effects import EFFECTS, Effect

    kind, _, name = mutation.partition(":")
    if kind == "effect":
        effect = EFFECTS[name]
        methods = ("input", "output", "parallel", "backlash")
        methods += ("input_with_state", "output_with_state", "parallel_with_state")
        # its own or inherited from another effect (a variant such as
        # backlash_friction_contacts): replaced on this class only
        deleted = [m for m in methods if getattr(effect, m) is not getattr(Effect, m)]
        if not deleted:
            raise SystemExit(f"mutation {mutation}: {effect.__name__} overrides none of {methods}")
        for method in deleted:
            setattr(effect, method, vars(Effect)[method])
    elif kind == "starts":
        EFFECTS[name].starts = classmethod(lambda cls, model, u, y, residual: [])
    elif kind == "contacts":
        from jaxcascade._measured._effects import BacklashFriction, BacklashFrictionContacts

        BacklashFrictionContacts.start_fractions = BacklashFriction.start_fractions
    elif kind == "noise":
        from jaxcascade._measured._noise import ARNoise

        ARNoise.fit_records = classmethod(lambda cls, residuals, *a, **k: (ARNoise.white(), 1.0))
    elif kind == "pem":
        import jax.numpy as jnp

        from jaxcascade._estimator import _pem
        from jaxcascade._status import Status

        def no_iteration(evaluate, z0, **settings):
            w = evaluate(z0)[0]
            converged = jnp.asarray(int(Status.converged), jnp.int32)
            return z0, jnp.mean(w**2), converged, jnp.asarray(0, jnp.int32)

        _pem.levenberg_marquardt = no_iteration
    elif kind == "robust":
        from jaxcascade._estimator import _robust

        _robust._multistart = lambda u, y, key, stage, **settings: stage.solution
    else:
        raise SystemExit(f"mutation {mutation!r}: unknown (see benchmarks/mutation_plugin.py)")
