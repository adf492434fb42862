"""jaxcascade: identification of three-block cascade systems with backlash (Vörös 2016).

The model (`CascadeParams`, `Orders`), its simulator (`simulate`, `measure`), the
paper's iterative estimator (`voros`) and a robust multi-start output-error estimator
(`robust`), a batched Monte-Carlo engine (`Spec`, `run`, `summarise`), measured-data
tools (`read_record`, `residual_tests`) and the model-error loop (`model_error_loop`).
Nothing here changes JAX's configuration: enable float64 yourself where you need it.
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
from ._diagnose_plot import (
    plot_residual_tests as plot_residual_tests,
    residual_figures as residual_figures,
    save_residual_figures as save_residual_figures,
)
from ._effects import (
    EFFECTS as EFFECTS,
    Effect as Effect,
    ExtendedModel as ExtendedModel,
    simulate_extended as simulate_extended,
)
from ._estimate import Solution as Solution, initial_guess as initial_guess, voros as voros
from ._estimator._robust import robust as robust
from ._estimators import ESTIMATORS as ESTIMATORS
from ._examples import EXAMPLES as EXAMPLES, Example as Example, example as example
from ._loop import LoopResult as LoopResult, model_error_loop as model_error_loop
from ._metrics import fit_percent as fit_percent, nrmse as nrmse
from ._model import (
    CascadeParams as CascadeParams,
    Orders as Orders,
    is_admissible as is_admissible,
    is_stable as is_stable,
)
from ._montecarlo import (
    cell_key as cell_key,
    chunk_memory as chunk_memory,
    run as run,
    run_chunk as run_chunk,
    run_realisation as run_realisation,
)
from ._plot import plot_sweep as plot_sweep
from ._prior import random_system as random_system
from ._refine import refine as refine
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
from ._spec import Cell as Cell, Spec as Spec
from ._status import Status as Status, status_names as status_names
from ._tables import (
    compare as compare,
    read_metadata as read_metadata,
    read_summary as read_summary,
    summarise as summarise,
)

__version__ = "0.1.0"
