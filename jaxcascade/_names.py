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

# the effect library of the model-error loop, in the registry's order: name: one-line
# description (`Effect.description`)
EFFECTS = {
    "output_offset": "constant offset added to the output: y + d",
    "input_delay": "pure input delay of d samples: u(t - d)",
    "dynamics_order": (
        "more poles or zeros in the linear block: one more (p + 1, r + 1), or up to the "
        "orders of the linear model the validation records choose"
    ),
    "pwl_segment": "one more breakpoint (segment) in the static input nonlinearity",
    "output_saturation": "output clipped to [lower, upper] (a sensor or actuator limit)",
    "output_drift": "linear drift of the output over the record: y + d t / 1000 (t in samples)",
    "output_feedthrough": "parallel linear path from x to the output: y + d x",
    "slack_friction": (
        "friction behind a slack zone: stop operator (threshold r) then a dead zone (|s| "
        "<= dead r) and plateaus upper, lower"
    ),
    "backlash_friction": (
        "Coulomb friction (levels upper, lower) behind a slack (half-width gap) through a"
        " contact of stiffness k, averaged over the rotor's unknown start in the slack"
    ),
    "backlash_friction_contacts": (
        "backlash_friction with the rotor starting at rest against either side of the "
        "slack (mean of the two)"
    ),
    "prandtl_ishlinskii": (
        "Prandtl-Ishlinskii sum of stop operators (thresholds on a grid, fixed) and "
        "hinges of each, linear in the weights"
    ),
    "dahl_friction": (
        "Dahl friction: dF = sigma du (1 - F/level sgn du), in parallel with the cascade"
    ),
    "input_backlash": (
        "backlash (play operator, half-width gap) in front of the static nonlinearity"
    ),
    "general_backlash": (
        "curved branches of the output backlash (general backlash, polynomial degree 2-3)"
    ),
    "nonlinear_feedback": (
        "polynomial of the linear block's past output fed back into it: x(t) + k2 "
        "x(t-1)^2 + k3 x(t-1)^3 (a Duffing spring, a Lur'e loop)"
    ),
    "direct_term": (
        "the input acting within the sample: x(t) + d v(t) (a zero at lag 0 of sampled "
        "continuous dynamics)"
    ),
    "velocity_friction": (
        "Coulomb friction on the velocity of an integrating plant: x(t) - clip(x(t), -f-,"
        " f+), it stops a slow motion, never reverses it (positioning systems; "
        "--integrate)"
    ),
    "output_polynomial": (
        "static polynomial map of the output: y + c0 + c2 y^2 + c3 y^3 (a Wiener "
        "structure: a saturating or square-law sensor or output stage)"
    ),
    "output_fold": (
        "output folded at a level: c0 + c1 |y - s| + c2 (y - s)^2 (a sign-blind sensor, "
        "|speed|; a rectifier)"
    ),
    "output_dynamics": (
        "linear dynamics after the cascade and its output map: (1 + beta q^-1 ..) / (1 + "
        "alpha q^-1 ..) y + c (a Wiener-Hammerstein sandwich)"
    ),
    "inner_polynomial": (
        "static polynomial map between the cascade and output_dynamics added before it: "
        "y + c0 + c2 y^2 + c3 y^3 (the static part of a Wiener-Hammerstein sandwich)"
    ),
    "inner_kink": (
        "two-slope static map between the cascade and output_dynamics added before it: "
        "y + c0 + c1 |y - s| (a diode, a rectifier stage that conducts "
        "more one way: the static part of a Wiener-Hammerstein circuit)"
    ),
}

# the loop's noise model, considered beside the effects, and its description
NOISE_MODEL = "colored_noise"
NOISE_MODEL_DESCRIPTION = "autoregressive output noise e(t) = w(t) + c1 e(t-1) + ... + cq e(t-q)"

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
