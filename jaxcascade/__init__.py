"""jaxcascade: identification of three-block cascade systems with backlash (Vörös 2016).

    u -> NS (piecewise linear) -> v -> LD (linear difference equation) -> x -> ND (backlash) -> y

Model and simulation
    `Orders`, `CascadeParams`, `is_admissible`, `is_stable`; `simulate`, `signals`,
    `measure`, `add_noise`, `uniform_input`, `pwl`, `linear_block`, `backlash`;
    `example`, `EXAMPLES`, `Example` (the paper's two examples); `random_system` (the
    random-system prior).
Inputs and noise of an experiment
    `INPUTS`, `input_design`, `InputDesign` (uniform, gaussian, multisine, multilevel,
    file: `input_design(kind, **settings)(key, n)` draws one record); `NOISES`,
    `disturbance`, `Disturbance` (white, ar, arma, student_t, outliers: unit-variance
    noise for `add_noise(key, y, snr, noise)`).
Estimators (each fits one record and returns a `Solution` with a `Status`)
    `Literal` / `voros` (the paper's iteration, eqs. 19-28), `Robust` / `robust`
    (output-error least squares from the literal estimate, multi-start fallback),
    `refine`; `Pem` / `pem` / `pem_fit` (prediction error with an AR noise model, for
    coloured output noise); the registry `ESTIMATORS` and `estimator` (`estimator(name,
    **settings)`); `register_estimator` (a user's own: an `Estimator` class or a host
    function `fn(u, y, orders) -> vector`; also the entry-point group
    `jaxcascade.estimators`); `Estimator`, the interface; `initial_guess`,
    `regression` (the key-term regression, eqs. 15-18); `status_names` (codes to
    names); `solution_table` (a `Solution` of any batch shape, e.g. after `jax.vmap`, as
    a pandas DataFrame, one row per record).
    Records are checked before any work: one 1-D record of real, finite numbers (lists
    and NumPy arrays are converted), `u` and `y` of equal length, at least
    `Orders.min_samples` samples; anything else is a `ValueError` or `TypeError` saying
    what to change.
Efficiency
    `jacobian` (of the simulated output), `fisher_information`, `crlb` (the Cramer-Rao
    bound on each parameter's standard deviation; white or coloured noise: `poles`,
    `zeros`), `information_factor` (how much lower a heavy-tailed density's exact bound
    is), `standard_errors` (of a fit).
Monte-Carlo sweeps
    `Spec`, `Cell`, `run`, `run_chunk`, `run_realisation`, `cell_key`, `chunk_memory`;
    `summarise`, `compare_sweeps` (a sweep's summary against a baseline's; `compare`,
    its deprecated alias, goes in the next release), `read_summary`, `read_metadata`;
    `plot_sweep`.
On-line identification and systems that change
    `Recursive` / `recursive` (the key-term regression by recursive least squares with
    forgetting, the paper's closing remark); `Change`, `trajectory`,
    `simulate_changing` (a parameter that steps or drifts, and the cascade simulated
    with it); `tracking`, `Tracking` (the tracking study of one change),
    `tracking_summary` and `plot_tracking` (re-entry, steady RMSE and the median error
    trajectory of a sweep with `[system.change]`).
Every measured-data command as one call (the command's defaults, a result object with
    the status and warnings the command prints, `to_dict()`, the command's JSON)
    `fit_record` -> `FitResult` (`jaxcascade fit`: estimates and standard errors in the
    record's units); `loop_records`, `loop_benchmark` -> `LoopRun` (`jaxcascade loop`,
    on records or on a benchmark by name and root; `report(folder)` writes what `--report`
    writes); `simulate_model` -> `Simulation` (`jaxcascade simulate`).
Measured data and the model-error loop
    `read_record`, `record_from_arrays`, `split_record`, `Record`, `Scaling`;
    `residual_tests`, `ResidualTests`, `regime_from_switches`, `plot_residual_tests`,
    `residual_figures`, `save_residual_figures`; `model_error_loop`, `LoopResult`,
    `EFFECTS`, `Effect`, `ExtendedModel`, `simulate_extended`, `ARNoise`; `ARX`,
    `fit_arx`, `best_arx`; `nrmse`, `fit_percent`; `load_model`, `SavedModel` (a model
    file of `loop --report` or `fit --save-model`: `simulate(u)`, `score(u, y)`,
    `compare(record)`, `save(path)`); `benchmark_data`, `Benchmark`,
    `BenchmarkRecord`, `BENCHMARKS` (the community's benchmarks of nonlinearbenchmark.org,
    read from their MAT files and split as the official loader `nonlinear-benchmarks` does,
    with each test record's `n_init` and the published baselines).

Nothing here changes JAX's configuration: enable float64 yourself where you need it
(`jax.config.update("jax_enable_x64", True)`); the command line does.
"""

# The public names are imported on first use (PEP 562), so that `import jaxcascade` and
# the command line's `--help` do not import JAX; `dir(jaxcascade)` lists them all.

import importlib as _importlib

from ._version import __version__ as __version__

# module: the public names it provides
_MODULES = {
    "._measured._arx": (
        "ARX",
        "best_arx",
        "fit_arx",
    ),
    "._measured._benchmark_data": (
        "BENCHMARKS",
        "Benchmark",
        "BenchmarkRecord",
        "benchmark_data",
    ),
    "._experiment._changing": (
        "Change",
        "simulate_changing",
        "trajectory",
    ),
    "._data": (
        "Record",
        "Scaling",
        "read_record",
        "record_from_arrays",
        "split_record",
    ),
    "._measured._diagnose": (
        "ResidualTests",
        "regime_from_switches",
        "residual_tests",
    ),
    "._estimator._efficiency": (
        "crlb",
        "fisher_information",
        "information_factor",
        "jacobian",
        "standard_errors",
    ),
    "._measured._effects": (
        "EFFECTS",
        "Effect",
        "ExtendedModel",
        "simulate_extended",
    ),
    "._estimator": (
        "ESTIMATORS",
        "Estimator",
        "Solution",
        "estimator",
        "register_estimator",
        "solution_table",
    ),
    "._estimator._literal": (
        "Literal",
        "initial_guess",
        "voros",
    ),
    "._estimator._pem": (
        "Pem",
        "pem",
        "pem_fit",
    ),
    "._estimator._recursive": (
        "Recursive",
        "recursive",
    ),
    "._estimator._refine": ("refine",),
    "._estimator._robust": (
        "Robust",
        "robust",
    ),
    "._system._examples": (
        "EXAMPLES",
        "Example",
        "example",
    ),
    "._measured._loop": (
        "LoopResult",
        "model_error_loop",
    ),
    "._measured._model_file": (
        "SavedModel",
        "load_model",
    ),
    "._workflow._fit": (
        "FitResult",
        "fit_record",
    ),
    "._workflow._loop": (
        "LoopRun",
        "loop_benchmark",
        "loop_records",
    ),
    "._workflow._simulate": (
        "Simulation",
        "simulate_model",
    ),
    "._metrics": (
        "fit_percent",
        "nrmse",
    ),
    "._system._model": (
        "CascadeParams",
        "Orders",
        "is_admissible",
        "is_stable",
    ),
    "._montecarlo._engine": (
        "cell_key",
        "chunk_memory",
        "run_chunk",
        "run_realisation",
    ),
    "._montecarlo._run": ("run",),
    "._montecarlo._spec": (
        "Cell",
        "Spec",
    ),
    "._montecarlo._tables": (
        "compare",
        "compare_sweeps",
        "read_metadata",
        "read_summary",
        "summarise",
        "tracking_summary",
    ),
    "._montecarlo._tracking": (
        "Tracking",
        "tracking",
    ),
    "._measured._noise": ("ARNoise",),
    "._experiment._disturbance": (
        "Disturbance",
        "NOISES",
        "disturbance",
    ),
    "._experiment._inputs": (
        "INPUTS",
        "InputDesign",
        "input_design",
    ),
    "._plot._residuals": (
        "plot_residual_tests",
        "residual_figures",
        "save_residual_figures",
    ),
    "._plot._sweep": ("plot_sweep",),
    "._plot._tracking": ("plot_tracking",),
    "._system._prior": ("random_system",),
    "._estimator._regression": ("regression",),
    "._system._simulate": (
        "add_noise",
        "backlash",
        "linear_block",
        "measure",
        "pwl",
        "signals",
        "simulate",
        "uniform_input",
    ),
    "._status": (
        "Status",
        "status_names",
    ),
}
_EXPORTS = {name: module for module, names in _MODULES.items() for name in names}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'jaxcascade' has no attribute {name!r}")
    value = getattr(_importlib.import_module(module, __name__), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})
