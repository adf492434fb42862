"""The names in the package's registries, as plain strings, for the command line's help.

Building `--help` must not import JAX (it then answers at once), so the names it lists
live here as well as in their registries (`_estimator.ESTIMATORS`, `_effects.EFFECTS`,
`_noise.ARNoise`, `_montecarlo._spec.FAMILIES`, `_benchmark._robust.SYSTEMS`,
`_inputs.INPUTS`, `_disturbance.NOISES`);
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
    "general_backlash",
    "nonlinear_feedback",
    "direct_term",
    "velocity_friction",
    "output_polynomial",
    "output_fold",
    "output_dynamics",
)

# the loop's noise model, considered beside the effects
NOISE_MODEL = "colored_noise"

# input designs of a sweep: name: one-line summary (`InputDesign.summary`)
INPUTS = {
    "uniform": "independent samples uniform in (-A, A) (the paper's, A = 2)",
    "gaussian": "independent zero-mean Gaussian samples (std)",
    "multisine": "random-phase multisine on lines in a band (fractions of Nyquist)",
    "multilevel": "random levels held between random switches (levels = 2: binary)",
    "file": "random segments of a column of a CSV/Parquet record",
}

# output noise kinds of a sweep: name: one-line summary (`Disturbance.summary`)
NOISES = {
    "white": "white Gaussian noise (the paper's)",
    "ar": "stationary AR noise (poles real or [radius, angle] pairs)",
    "arma": "stationary ARMA noise (poles and zeros real or [radius, angle] pairs)",
    "student_t": "white Student-t noise (dof > 2 degrees of freedom)",
    "outliers": "Gaussian noise plus outliers (fraction, size in stds)",
}

# system families of a sweep
FAMILIES = ("random",)

# systems of `jaxcascade bench --estimator robust`
BENCH_SYSTEMS = ("example1", "example2", "random")
