"""The names in the package's registries, as plain strings, for the command line's help.

Building `--help` must not import JAX (it then answers at once), so the names it lists
live here as well as in their registries (`_estimator.ESTIMATORS`, `_effects.EFFECTS`,
`_noise.ARNoise`, `_montecarlo._spec.FAMILIES`, `_benchmark._robust.SYSTEMS`);
`tests/test_names.py` holds each list equal to its registry.
"""

# name: one-line summary (`Estimator.summary`)
ESTIMATORS = {
    "literal": "the paper's iteration (eqs. 19-28) from its initial values",
    "robust": "output-error Levenberg-Marquardt from the literal estimate, multi-start fallback",
    "pem": "prediction error with an AR noise model (order by BIC), from the robust estimate",
    "recursive": "the key-term regression (eqs. 16-18) by recursive least squares with forgetting",
}

# the effect library of the model-error loop, in the registry's order
EFFECTS = (
    "output_offset",
    "input_delay",
    "dynamics_order",
    "pwl_segment",
    "output_saturation",
    "output_drift",
    "output_feedthrough",
    "slack_friction",
    "backlash_friction",
    "backlash_friction_contacts",
    "prandtl_ishlinskii",
    "dahl_friction",
    "input_backlash",
)

# the loop's noise model, considered beside the effects
NOISE_MODEL = "colored_noise"

# system families of a sweep
FAMILIES = ("random",)

# systems of `jaxcascade bench --estimator robust`
BENCH_SYSTEMS = ("example1", "example2", "random")
