"""jaxcascade: identification of three-block cascade systems with backlash (Vörös 2016).

    u -> NS (piecewise linear) -> v -> LD (linear difference equation) -> x -> ND (backlash) -> y

Model and simulation
    `Orders`, `CascadeParams`, `is_admissible`, `is_stable`; `simulate`, `signals`,
    `measure`, `add_noise`, `uniform_input`, `pwl`, `linear_block`, `backlash`;
    `example`, `EXAMPLES`, `Example` (the paper's two examples); `random_system` (the
    random-system prior).
Estimators (each fits one record and returns a `Solution` with a `Status`)
    `Literal` / `voros` (the paper's iteration, eqs. 19-28), `Robust` / `robust`
    (output-error least squares from the literal estimate, multi-start fallback),
    `refine`; the registry `ESTIMATORS` and `estimator` (`estimator(name, **settings)`);
    `Estimator`, the interface; `initial_guess`, `regression` (the key-term regression,
    eqs. 15-18); `status_names` (codes to names).
    Records are checked before any work: one 1-D record of real, finite numbers (lists
    and NumPy arrays are converted), `u` and `y` of equal length, at least
    `Orders.min_samples` samples; anything else is a `ValueError` or `TypeError` saying
    what to change.
Efficiency
    `jacobian` (of the simulated output), `fisher_information`, `crlb` (the Cramer-Rao
    bound on each parameter's standard deviation), `standard_errors` (of a fit).
Monte-Carlo sweeps
    `Spec`, `Cell`, `run`, `run_chunk`, `run_realisation`, `cell_key`, `chunk_memory`;
    `summarise`, `compare`, `read_summary`, `read_metadata`; `plot_sweep`.
Measured data and the model-error loop
    `read_record`, `record_from_arrays`, `split_record`, `Record`, `Scaling`;
    `residual_tests`, `ResidualTests`, `regime_from_switches`, `plot_residual_tests`,
    `residual_figures`, `save_residual_figures`; `model_error_loop`, `LoopResult`,
    `EFFECTS`, `Effect`, `ExtendedModel`, `simulate_extended`, `ARNoise`; `ARX`,
    `fit_arx`, `best_arx`; `nrmse`, `fit_percent`.

Nothing here changes JAX's configuration: enable float64 yourself where you need it
(`jax.config.update("jax_enable_x64", True)`); the command line does.
"""

from ._arx import ARX as ARX, best_arx as best_arx, fit_arx as fit_arx
from ._data import (
    Record as Record,
    Scaling as Scaling,
    read_record as read_record,
    record_from_arrays as record_from_arrays,
    split_record as split_record,
)
from ._diagnose import (
    ResidualTests as ResidualTests,
    regime_from_switches as regime_from_switches,
    residual_tests as residual_tests,
)
from ._efficiency import (
    crlb as crlb,
    fisher_information as fisher_information,
    jacobian as jacobian,
    standard_errors as standard_errors,
)
from ._effects import (
    EFFECTS as EFFECTS,
    Effect as Effect,
    ExtendedModel as ExtendedModel,
    simulate_extended as simulate_extended,
)
from ._estimator import (
    ESTIMATORS as ESTIMATORS,
    Estimator as Estimator,
    Solution as Solution,
    estimator as estimator,
)
from ._estimator._literal import Literal as Literal, initial_guess as initial_guess, voros as voros
from ._estimator._refine import refine as refine
from ._estimator._robust import Robust as Robust, robust as robust
from ._examples import EXAMPLES as EXAMPLES, Example as Example, example as example
from ._loop import LoopResult as LoopResult, model_error_loop as model_error_loop
from ._metrics import fit_percent as fit_percent, nrmse as nrmse
from ._model import (
    CascadeParams as CascadeParams,
    Orders as Orders,
    is_admissible as is_admissible,
    is_stable as is_stable,
)
from ._montecarlo._engine import (
    cell_key as cell_key,
    chunk_memory as chunk_memory,
    run_chunk as run_chunk,
    run_realisation as run_realisation,
)
from ._montecarlo._run import run as run
from ._montecarlo._spec import Cell as Cell, Spec as Spec
from ._montecarlo._tables import (
    compare as compare,
    read_metadata as read_metadata,
    read_summary as read_summary,
    summarise as summarise,
)
from ._noise import ARNoise as ARNoise
from ._plot._residuals import (
    plot_residual_tests as plot_residual_tests,
    residual_figures as residual_figures,
    save_residual_figures as save_residual_figures,
)
from ._plot._sweep import plot_sweep as plot_sweep
from ._prior import random_system as random_system
from ._regression import regression as regression
from ._simulate import (
    add_noise as add_noise,
    backlash as backlash,
    linear_block as linear_block,
    measure as measure,
    pwl as pwl,
    signals as signals,
    simulate as simulate,
    uniform_input as uniform_input,
)
from ._status import Status as Status, status_names as status_names
from ._version import __version__ as __version__
