"""Experiment specification of a Monte-Carlo sweep: a dataclass and its TOML form.

A spec names one system (a paper example, explicit parameters and orders, or a family of
random systems with one true system drawn per realisation), the input design
(`_inputs`), the output noise (`_disturbance`), and a grid of sample sizes x SNRs x
estimators; each grid cell runs `realisations` independent records. Everything is
validated at construction, so a bad spec fails with one sentence before any work
starts; a true breakpoint outside the interval the input covers is a warning
(`InputRangeWarning`: that segment cannot be identified).

TOML layout (every key optional except the system):

    example = 1                      # or "general1" / "general2" (curved branches),
                                     # or a [system] table, or system = "random"
    n = [500, 1000, 4000]
    snr = [10, 25, 50]               # sqrt(var y / var e); inf = noise-free
    realisations = 500
    seed = 0
    estimators = ["literal"]
    chunk_size = 64                  # default: 64 on a CPU, 1000 on an accelerator
    workers = 1                      # chunks at once in this process's threads
    scheduler = "tcp://HOST:8786"    # optional: run the chunks on a Dask cluster

    [input]
    kind = "uniform"                 # uniform, gaussian, multisine, multilevel, file
    amplitude = 2.0                  # or rms = 1.1547; `distribution` = old name of kind
    # gaussian: std | multisine: band = [0.0, 0.5], lines = 0 | multilevel: levels = 0,
    # switch_probability = 0.5 | file: path, column, segment = "random" or "whole",
    # decimate = 1, normalise = "record" or "segment"

    [noise]
    kind = "white"                   # white, ar, arma, student_t, outliers
    # ar: poles = [0.9] (a resonance: [[radius, angle]]) | arma: poles, zeros |
    # student_t: dof = 3 |
    # outliers: fraction = 0.02, size = 10 (in the Gaussian part's stds)

    [system]                         # instead of `example`
    orders = "2,2,2,2"               # optional, inferred from the names; a fifth
                                     # number is the backlash branches' degree (with
                                     # mL2.., mR2.. among the params)
    params = { MR1 = 1.2, MR2 = -1.4, DR1 = 1.0, ... }

    [system]                         # or: the random family (`_prior.random_system`)
    family = "random"                # same as the top-level `system = "random"`
    orders = "2,2,2,2"               # optional, default 2,2,2,2

    [estimator.literal]              # settings passed to the estimator
    max_iterations = 50

    [system.change]                  # optional: a system that changes (`_changing`)
    parameter = "cR"                 # steps at sample `at` to `to`, or drifts by
    at = 2000                        # `drift` per sample from `at` on; only the
    to = 0.45                        # on-line estimator `recursive` runs on it
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import pathlib
import tomllib
import warnings
from collections.abc import Mapping
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._estimator import estimator
from .._experiment._changing import Change, trajectory
from .._experiment._disturbance import NOISES, Disturbance, disturbance
from .._experiment._inputs import INPUTS, InputDesign, input_design
from .._system._examples import EXAMPLES as PAPER_EXAMPLES
from .._system._general_backlash import GENERAL_EXAMPLES
from .._system._model import CascadeParams, Orders

INPUT_KINDS = tuple(INPUTS)
NOISE_KINDS = tuple(NOISES)
# Families of systems: every realisation draws its own true system from a prior.
FAMILIES = ("random",)
# The issue-4 benchmark family: N = 3000, SNR 30 unless the spec says otherwise.
_FAMILY_DEFAULTS = {"random": {"n": 3000, "snr": 30.0}}

_TOP_LEVEL = (
    "example",
    "system",
    "input",
    "noise",
    "n",
    "snr",
    "realisations",
    "seed",
    "estimators",
    "estimator",
    "chunk_size",
    "workers",
    "scheduler",
)

# The systems a spec's `example` names: the paper's (1, 2) and the general backlash's
# ("general1", "general2": curved branches, `Orders.degree` 3; docs/general_backlash.md).
EXAMPLES = {
    **PAPER_EXAMPLES,
    **{name: ex.example() for name, ex in GENERAL_EXAMPLES.items()},
}


class InputRangeWarning(UserWarning):
    """A true breakpoint lies outside the interval the spec's input covers."""


class Cell(NamedTuple):
    """One grid cell of a sweep: sample size, SNR and estimator name."""

    n: int
    snr: float
    estimator: str


def _as_tuple(value, kind, name) -> tuple:
    values = value if isinstance(value, list | tuple) else [value]
    if not values:
        raise ValueError(f"Spec field {name!r} needs at least one value.")
    out = []
    for v in values:
        if isinstance(v, bool):
            raise ValueError(f"Spec field {name!r} must hold numbers, got {v!r}.")
        try:
            converted = kind(v)
        except (TypeError, ValueError):
            raise ValueError(f"Spec field {name!r} must hold numbers, got {v!r}.") from None
        if kind is int and converted != v:
            raise ValueError(f"Spec field {name!r} must hold integers, got {v!r}.")
        out.append(converted)
    if len(set(out)) != len(out):
        raise ValueError(f"Spec field {name!r} repeats a value: {list(values)}.")
    return tuple(out)


def _freeze(value, what: str = "Estimator"):
    # Settings are static under jit, so they must be hashable: TOML arrays become tuples.
    if isinstance(value, list | tuple):
        return tuple(_freeze(v, what) for v in value)
    if isinstance(value, bool | int | float | str):
        return value
    raise ValueError(f"{what} settings must be numbers, strings or arrays, got {value!r}.")


def _frozen_table(settings: Mapping[str, Any]) -> dict[str, Any]:
    return {key: _freeze(value) for key, value in sorted(settings.items())}


def _listed(table: Mapping[str, Any]) -> dict[str, Any]:
    def plain(value):
        return [plain(v) for v in value] if isinstance(value, tuple) else value

    return {key: plain(value) for key, value in table.items()}


def hash_words(text: str) -> np.ndarray:
    """The 64-bit BLAKE2b hash of `text` as two 32-bit words (keys are folded with them)."""
    digest = hashlib.blake2b(text.encode(), digest_size=8).digest()
    return np.frombuffer(digest, dtype="<u4")


def _exact(value):
    """Settings as canonical JSON values, floats in exact hex form."""
    if isinstance(value, dict):
        return {k: _exact(v) for k, v in sorted(value.items())}
    if isinstance(value, list | tuple):
        return [_exact(v) for v in value]
    if isinstance(value, float):
        return value.hex()
    return value


def _change_identity(change: Change) -> dict:
    """A one-parameter change keeps the key it had before several could change."""
    several = isinstance(change.parameter, tuple)
    out = {"parameter": list(change.parameter) if several else change.parameter}
    out["at"] = int(change.at)
    for name in ("to", "drift"):
        value = getattr(change, name)
        if value is not None:
            out[name] = [float(v).hex() for v in value] if several else float(value).hex()
    return out


# Realisations per compiled chunk by default: on a CPU cache-sized batches run fastest;
# on an accelerator (`_scans.parallel`) a chunk is a few large kernels per iteration
# and its launches and loop steps cost the same at 64 records as at 1000, while 1000
# records of N 4000 need a few GB of device memory (the robust estimator's Jacobians,
# the Cramér-Rao bound's tangents): a sweep of any length stays within that.
CHUNK_SIZE = {"cpu": 64, "accelerator": 1000}


def default_chunk_size() -> int:
    """The default `Spec.chunk_size` on this process's default backend (`CHUNK_SIZE`)."""
    from .._system import _scans

    return CHUNK_SIZE["accelerator" if _scans.parallel() else "cpu"]


@dataclasses.dataclass(frozen=True)
class Spec:
    """A Monte-Carlo experiment: one system, a grid `n x snr x estimators`, realisations.

    - `example`: paper example number (1 or 2), a general-backlash example (`"general1"`,
      `"general2"`: curved branches of degree 3), or `None` when `params` is given.
    - `params`: explicit true values `{name: value}`; `orders` (an `Orders` or
      `"nR,nL,r,p"`) defaults to the orders implied by the names.
    - `family`: `"random"`, the random-system prior of `_prior.random_system` (with
      `u_max = amplitude`): realisation `i` draws its own true system from a key folded
      from its realisation key, so every estimator of a sweep sees the same system and
      record; `orders` default `2,2,2,2`, `n` 3000 and `snr` 30.
    - `input`, `input_settings`: the input design's kind (`_inputs.INPUTS`) and its
      settings (scale: `amplitude` or `rms`); `amplitude` is a shorthand for
      `input_settings["amplitude"]`, and after construction holds the design's `bound`
      (its amplitude, or that of the uniform input of the same power). The settings are
      stored resolved (defaults filled in), so a spec records what it drew.
    - `noise`, `noise_settings`: the output noise's kind (`_disturbance.NOISES`) and its
      settings, stored resolved; the SNR is `sqrt(var y / var e)` of the noise as added.
    - `n`, `snr`: sample sizes and SNRs (`sqrt(var y / var e)`, `inf` = noise-free);
      default the example's own (N, 25).
    - `realisations`: records per grid cell; `seed`: the sweep's PRNG seed.
    - `estimators`: names in `ESTIMATORS`; `settings`: `{name: {setting: value}}`.
    - `chunk_size`: realisations per jit-compiled batch; it bounds peak memory and
      never changes a result. Default `default_chunk_size()`: 64 on a CPU, 1000 on an
      accelerator.
    - `workers`: chunks run at once in this process, each in its own host thread
      (default 1). XLA runs a chunk's scans and loops in one thread, so on a machine
      with more cores `workers = 2` or more raises the throughput (robust on Example 2,
      64-record chunks on 2 cores: 1.5x); the rows are the same bit for bit, peak memory
      grows with it, and the timing columns then include the chunks' contention for the
      cores (keep 1 to compare estimators' times per fit). Ignored with a `scheduler`
      and for host estimators (run one record after another in this thread).
    - `scheduler`: address of a Dask scheduler (`tcp://HOST:PORT`) to run the chunks on,
      or `None` to run them in this process. Like `chunk_size` it is how the sweep runs,
      not what it computes: it never changes a result, and it is left out of the
      identity that a resumed run must match.
    - `change`: a `Change` (or its `[system.change]` table) of a fixed system: the
      records come from the changed system (`_changing`), `true_<name>` is the system at
      the end, and the tracking columns (`_engine`) are filled. Only `recursive` runs
      on it; its `every` (the spacing of the recorded trajectory) defaults to 10.
    """

    example: int | str | None = None
    params: Mapping[str, float] | None = None
    family: str | None = None
    orders: Orders | str | None = None
    input: str = "uniform"
    amplitude: float | None = None
    input_settings: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    noise: str = "white"
    noise_settings: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    n: tuple[int, ...] | None = None
    snr: tuple[float, ...] | None = None
    realisations: int = 100
    seed: int = 0
    estimators: tuple[str, ...] = ("literal",)
    settings: Mapping[str, Mapping[str, Any]] = dataclasses.field(default_factory=dict)
    chunk_size: int | None = None
    workers: int = 1
    scheduler: str | None = None
    change: Change | Mapping | None = None

    def __post_init__(self):
        set_ = object.__setattr__
        if sum(x is not None for x in (self.example, self.params, self.family)) != 1:
            raise ValueError(
                "A spec needs exactly one system: an example number, explicit params or "
                "a family ('random')."
            )
        if self.family is not None:
            if self.family not in FAMILIES:
                raise ValueError(
                    f"Unknown system family {self.family!r}; known: {', '.join(FAMILIES)}."
                )
            orders = Orders.parse(self.orders) if isinstance(self.orders, str) else self.orders
            if orders is not None and orders.degree > 1:
                raise ValueError(
                    f"The {self.family!r} family draws straight backlash branches; orders "
                    f"{orders} have a branch degree: give explicit params (with the "
                    "curvature terms) or example 'general1' / 'general2'."
                )
            set_(self, "orders", orders if orders is not None else Orders())
            defaults = _FAMILY_DEFAULTS[self.family]
            set_(self, "n", self.n if self.n is not None else defaults["n"])
            set_(self, "snr", self.snr if self.snr is not None else defaults["snr"])
        elif self.example is not None:
            if isinstance(self.example, bool) or self.example not in EXAMPLES:
                raise ValueError(
                    f"Unknown example {self.example!r}; the paper has examples "
                    f"{' and '.join(map(str, PAPER_EXAMPLES))}, the general backlash "
                    f"{' and '.join(GENERAL_EXAMPLES)}."
                )
            ex = EXAMPLES[self.example]
            orders = Orders.parse(self.orders) if isinstance(self.orders, str) else self.orders
            if orders is not None and orders != ex.orders:  # equal ones: dataclasses.replace
                raise ValueError("A spec with an example takes its orders from the example.")
            set_(self, "orders", ex.orders)
            set_(self, "n", self.n if self.n is not None else ex.n_samples)
            set_(self, "snr", self.snr if self.snr is not None else ex.snr)
        else:
            if not isinstance(self.params, Mapping):
                raise ValueError("Spec field 'params' must map parameter names to values.")
            orders = Orders.parse(self.orders) if isinstance(self.orders, str) else self.orders
            truth = CascadeParams.from_dict(dict(self.params), orders)  # checks invariants
            set_(self, "orders", truth.orders)
            set_(self, "params", truth.to_dict())
            if self.n is None:
                raise ValueError("A spec with explicit params needs the sample sizes 'n'.")
            set_(self, "snr", self.snr if self.snr is not None else 25.0)
        set_(self, "n", _as_tuple(self.n, int, "n"))
        set_(self, "snr", _as_tuple(self.snr, float, "snr"))
        set_(self, "estimators", _as_tuple(self.estimators, str, "estimators"))

        self._resolve_input_and_noise()
        low = self.orders.min_samples
        for n in self.n:
            if n < low:
                raise ValueError(
                    f"N = {n} is too small for orders {self.orders}: a record needs at "
                    f"least {low} samples ({Orders.SAMPLES_PER_PARAMETER} per parameter)."
                )
        design = self.input_design()
        for n in self.n:
            design.check(n)
        for snr in self.snr:
            if not snr > 0:
                raise ValueError(f"SNR must be positive (inf = noise-free), got {snr}.")
        if self.chunk_size is None:
            set_(self, "chunk_size", default_chunk_size())
        for name, value, lowest in (
            ("realisations", self.realisations, 1),
            ("chunk_size", self.chunk_size, 1),
            ("workers", self.workers, 1),
            ("seed", self.seed, 0),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or value < lowest:
                raise ValueError(
                    f"Spec field {name!r} must be an integer >= {lowest}, got {value!r}."
                )
        if self.seed >= 2**32:
            raise ValueError(f"Seed must be below 2**32, got {self.seed}.")
        if self.scheduler is not None and not (
            isinstance(self.scheduler, str) and ":" in self.scheduler.strip()
        ):
            raise ValueError(
                f"Scheduler must be an address like tcp://HOST:8786, got {self.scheduler!r}."
            )

        for name in self.estimators:
            estimator(name)
        if not isinstance(self.settings, Mapping):
            raise ValueError("Spec field 'settings' must map estimator names to tables.")
        settings = {}
        for name, table in self.settings.items():
            if name not in self.estimators:
                raise ValueError(
                    f"Settings given for estimator {name!r}, which the spec does not run."
                )
            if not isinstance(table, Mapping):
                raise ValueError(f"Settings of estimator {name!r} must be a table.")
            frozen = {key: _freeze(value) for key, value in sorted(table.items())}
            estimator(name, **frozen)  # unknown or ill-typed settings: one sentence
            settings[name] = frozen
        set_(self, "settings", settings)
        self._warn_breakpoints(design)
        if self.change is not None:
            self._check_change()
        # What a cell's identity and its fit need, resolved once here (plain values and
        # estimators without arrays, the same in every dtype and on every Dask worker):
        # the engine asks the spec instead of resolving them per chunk.
        set_(self, "_input_identity", _exact(design.identity()))
        set_(self, "_input_stamp", json.dumps(design.identity(), sort_keys=True, default=str))
        set_(
            self,
            "_fits",
            {name: estimator(name, **self.settings.get(name, {})) for name in self.estimators},
        )

    def _check_change(self) -> None:
        change = self.change
        if isinstance(change, Mapping):
            change = Change.from_table(change)
        if not isinstance(change, Change):
            raise ValueError("Spec field 'change' must be a [system.change] table.")
        if self.family is not None:
            raise ValueError("[system.change] needs a fixed system, not a family.")
        if self.estimators != ("recursive",):
            raise ValueError(
                "[system.change]: only the on-line estimator tracks a change; write "
                f'estimators = ["recursive"], not {list(self.estimators)}.'
            )
        if not change.at < min(self.n):
            raise ValueError(f"[system.change]: at = {change.at} is not inside N = {min(self.n)}.")
        trajectory(self.truth(), change, max(self.n))  # unknown name, inadmissible change
        settings = {**self.settings}
        settings["recursive"] = {"every": 10, **settings.get("recursive", {})}
        if settings["recursive"]["every"] < 1 or settings["recursive"].get("passes", 1) != 1:
            raise ValueError("[system.change]: the recursive estimator needs every >= 1, passes 1.")
        object.__setattr__(self, "change", change)
        object.__setattr__(self, "settings", settings)

    def _resolve_input_and_noise(self) -> None:
        set_ = object.__setattr__
        if not isinstance(self.input_settings, Mapping):
            raise ValueError("Spec field 'input_settings' must map setting names to values.")
        if not isinstance(self.noise_settings, Mapping):
            raise ValueError("Spec field 'noise_settings' must map setting names to values.")
        if self.input not in INPUTS:
            raise ValueError(
                f"Unknown input kind {self.input!r}; known kinds: {', '.join(INPUT_KINDS)}."
            )
        table = {k: _freeze(v, "Input") for k, v in self.input_settings.items()}
        scaled = {"amplitude", "rms", "std"} & set(table)
        if self.amplitude is not None and not scaled:
            table["amplitude"] = self.amplitude
        design = input_design(self.input, **table)
        # `amplitude` beside a scaled table (dataclasses.replace of a spec) must agree
        if self.amplitude is not None and scaled and self.amplitude != design.bound:
            raise ValueError(
                f"Input amplitude {self.amplitude!r} disagrees with the input's settings "
                f"{dict(table)}; give the scale once."
            )
        set_(self, "input_settings", _frozen_table(design.settings()))
        set_(self, "amplitude", float(design.bound))
        if self.noise not in NOISES:
            raise ValueError(
                f"Unknown noise kind {self.noise!r}; known kinds: {', '.join(NOISE_KINDS)}."
            )
        noise = disturbance(
            self.noise, **{k: _freeze(v, "Noise") for k, v in self.noise_settings.items()}
        )
        set_(self, "noise_settings", _frozen_table(noise.settings()))

    def _warn_breakpoints(self, design: InputDesign) -> None:
        if self.family is not None:  # the prior draws breakpoints inside the input's bound
            return
        values = self.true_values()
        names = [n for n in self.orders.names if n.startswith(("DR", "DL"))]
        for n in self.n:
            low, high = design.span(n)
            outside = [
                f"{name} = {values[name]:g}" for name in names if not low <= values[name] <= high
            ]
            if outside:
                warnings.warn(
                    f"The true breakpoint(s) {', '.join(outside)} lie outside the interval "
                    f"[{low:.3g}, {high:.3g}] that the {self.input} input covers at N = {n}: "
                    "the segment beyond cannot be identified; raise the input's amplitude.",
                    InputRangeWarning,
                    stacklevel=4,
                )
                return

    def input_design(self) -> InputDesign:
        """The input design of every realisation (`_inputs`); a file is read once."""
        return input_design(self.input, **dict(self.input_settings))

    def disturbance(self) -> Disturbance:
        """The output noise of every realisation (`_disturbance`)."""
        return disturbance(self.noise, **dict(self.noise_settings))

    # ---- derived ---------------------------------------------------------------------

    @property
    def system(self) -> str:
        """Label of the system in tables: `example1`, `example2`, `custom` or the family."""
        if self.family is not None:
            return self.family
        if isinstance(self.example, str):
            return self.example
        return f"example{self.example}" if self.example is not None else "custom"

    def truth(self, dtype=None) -> CascadeParams:
        """The true parameters (ValueError for a family: each realisation has its own)."""
        self._check_fixed()
        dtype = dtype or jnp.result_type(float)
        if self.example is not None:
            return EXAMPLES[self.example].params(dtype)
        return CascadeParams.from_dict(self.params, self.orders).astype(dtype)

    def true_values(self) -> dict[str, float]:
        self._check_fixed()
        values = EXAMPLES[self.example].values if self.example is not None else self.params
        return {name: float(values[name]) for name in self.orders.names}

    def _check_fixed(self) -> None:
        if self.family is not None:
            raise ValueError(
                f"The {self.family!r} family has no single true system: each realisation "
                "draws its own (see the true_<name> columns of the realisation table)."
            )

    def true_vector(self, dtype=None):
        """The true parameters as one vector in `orders.names` order (zeros for a family:
        each realisation draws its own, only the shape and dtype matter)."""
        dtype = dtype or jnp.result_type(float)
        if self.family is not None:
            return jnp.zeros((len(self.orders.names),), dtype)
        values = self.true_values()
        return jnp.asarray([values[name] for name in self.orders.names], dtype)

    @property
    def experiment(self) -> tuple:
        """The input design and noise as a hashable tuple (a cache key), with the input's
        identity as the spec read it (a file input's SHA-256)."""
        return (
            self.input,
            tuple(sorted(self.input_settings.items())),
            self.noise,
            tuple(sorted(self.noise_settings.items())),
            self._input_stamp,
        )

    def fit(self, name: str):
        """Estimator `name` of the spec with its settings."""
        return self._fits[name]

    def cell_identity(self, cell: Cell) -> str:
        """What a cell's records depend on, as canonical text (floats in exact hex form):
        the system, the input and its settings, the noise and its settings, a change,
        N and the SNR. Not the estimator, the chunking or the scheduler: every estimator
        of a sweep fits the same records, however the sweep runs."""
        if self.family is not None:
            system = {"family": self.family}
        else:
            system = {
                "values": {name: float(value).hex() for name, value in self.true_values().items()}
            }
        identity = {
            "orders": str(self.orders),
            **system,
            "input": self.input,
            "amplitude": float(self.amplitude).hex(),
            "n": int(cell.n),
            "snr": float(cell.snr).hex(),
        }
        if self.input != "uniform":
            identity["input_settings"] = self._input_identity
        if self.noise != "white":
            identity["noise"] = self.noise
            identity["noise_settings"] = _exact(dict(self.noise_settings))
        if self.change is not None:
            identity["change"] = _change_identity(self.change)
        return json.dumps(identity, sort_keys=True)

    def cell_key(self, cell: Cell):
        """`PRNGKey(seed)` folded with the 64-bit hash of `cell_identity` (two 32-bit
        words): realisation `i` of the cell uses `fold_in(cell_key, i)`."""
        key = jax.random.PRNGKey(np.uint32(self.seed))
        for word in hash_words(self.cell_identity(cell)):
            key = jax.random.fold_in(key, word)
        return key

    def cells(self) -> list[Cell]:
        """Grid cells in table order: N outermost, then SNR, then estimator."""
        return [Cell(n, snr, e) for n in self.n for snr in self.snr for e in self.estimators]

    def estimator_settings(self, name: str) -> tuple[tuple[str, Any], ...]:
        """Settings of estimator `name`, as a hashable sorted tuple of pairs."""
        return tuple(sorted(self.settings.get(name, {}).items()))

    # ---- (de)serialisation -----------------------------------------------------------

    def to_dict(self, *, chunk_size: bool = True) -> dict:
        """The spec in its TOML layout (JSON-serialisable; `from_dict` inverts it).

        `chunk_size=False` leaves out how the sweep runs (`chunk_size`, `workers`,
        `scheduler`): what remains is the experiment's identity, which a resumed run must
        match.
        """
        out: dict[str, Any] = {}
        if self.example is not None:
            out["example"] = self.example
        elif self.family is not None:
            out["system"] = {"family": self.family, "orders": str(self.orders)}
        else:
            out["system"] = {"orders": str(self.orders), "params": dict(self.params)}
        if self.change is not None:
            table = {k: v for k, v in dataclasses.asdict(self.change).items() if v is not None}
            out.setdefault("system", {})["change"] = _listed(table)
        out["input"] = {"kind": self.input, **_listed(self.input_settings)}
        out["noise"] = {"kind": self.noise, **_listed(self.noise_settings)}
        out["n"] = list(self.n)
        out["snr"] = list(self.snr)
        out["realisations"] = self.realisations
        out["seed"] = self.seed
        out["estimators"] = list(self.estimators)
        if self.settings:
            out["estimator"] = {
                name: {k: list(v) if isinstance(v, tuple) else v for k, v in table.items()}
                for name, table in self.settings.items()
            }
        if chunk_size:
            out["chunk_size"] = self.chunk_size
            if self.workers != 1:
                out["workers"] = self.workers
            if self.scheduler is not None:
                out["scheduler"] = self.scheduler
        return out

    def to_json(self, *, chunk_size: bool = True) -> str:
        return json.dumps(self.to_dict(chunk_size=chunk_size), sort_keys=True)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Spec:
        """Build from the TOML layout; unknown fields are an error."""
        unknown = [key for key in data if key not in _TOP_LEVEL]
        if unknown:
            raise ValueError(
                f"Unknown spec field {unknown[0]!r}; known fields: {', '.join(_TOP_LEVEL)}."
            )
        kwargs: dict[str, Any] = {}
        for key in (
            "example",
            "n",
            "snr",
            "realisations",
            "seed",
            "estimators",
            "chunk_size",
            "workers",
            "scheduler",
        ):
            if key in data:
                kwargs[key] = data[key]
        if "system" in data:
            system = data["system"]
            if isinstance(system, str):  # system = "random"
                system = {"family": system}
            system = _table(system, "system", ("params", "orders", "family", "change"))
            if "change" in system:
                kwargs["change"] = _table(system.pop("change"), "system.change", None)
                if "example" in data and not system:
                    system = None  # [system] holds only the change of an example
            if system is not None and "params" not in system and "family" not in system:
                raise ValueError("Spec table [system] needs 'params' or 'family'.")
            system = system or {}
            if "params" in system:
                kwargs["params"] = system["params"]
            if "family" in system:
                kwargs["family"] = system["family"]
            kwargs["orders"] = system.get("orders")
        if "input" in data:
            table = _table(data["input"], "input", None)
            kind = table.pop("kind", None)
            alias = table.pop("distribution", None)  # the old name of `kind`
            if kind is not None and alias is not None and kind != alias:
                raise ValueError(
                    "[input] gives kind and distribution (its old name) differently; "
                    "give kind only."
                )
            kwargs["input"] = kind or alias or "uniform"
            _known(table, "input", kwargs["input"], INPUTS)
            kwargs["input_settings"] = table
        if "noise" in data:
            table = _table(data["noise"], "noise", None)
            kwargs["noise"] = table.pop("kind", "white")
            _known(table, "noise", kwargs["noise"], NOISES)
            kwargs["noise_settings"] = table
        if "estimator" in data:
            kwargs["settings"] = _table(data["estimator"], "estimator", None)
        return cls(**kwargs)

    @classmethod
    def load(cls, path) -> Spec:
        """Read and validate a TOML spec file."""
        return cls.from_dict(read_toml(path))


def _meant(name: str, value) -> str:
    """What a plain value where a table belongs was most likely meant to say (a clause)."""
    shown = f"{value!r}" if not isinstance(value, str) else f'"{value}"'
    if name == "estimator":  # the settings table, confused with the list of estimators
        names = [value] if isinstance(value, str) else value
        if isinstance(names, list) and all(isinstance(n, str) for n in names):
            listed = ", ".join(f'"{n}"' for n in names)
            return (
                f" of settings per estimator ([estimator.robust] n_starts = 8); to choose "
                f"the estimators write estimators = [{listed}]"
            )
        return " of settings per estimator ([estimator.robust] n_starts = 8)"
    if name in ("input", "noise"):
        key = "kind" if isinstance(value, str) or name == "noise" else "amplitude"
        return f"; did you mean [{name}] {key} = {shown}?"
    if name == "system":
        return f'; did you mean [system] params = {{...}} or system = "random", not {shown}?'
    return ""


def read_toml(path) -> dict:
    """The contents of a TOML spec file; a `ValueError` naming the file when it is
    missing or not TOML."""
    path = pathlib.Path(path)
    if not path.is_file():
        raise ValueError(f"Spec file '{path}' does not exist.")
    try:
        with path.open("rb") as file:
            return tomllib.load(file)
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"Spec file '{path}' is not valid TOML: {error}.") from None


def _known(table: dict, name: str, kind, registry) -> None:
    """An unknown `[input]` / `[noise]` key is named with the kind's known settings."""
    if not isinstance(kind, str) or kind not in registry:
        return  # the spec names the unknown kind itself
    if name == "input":
        from .._experiment._inputs import known_settings

        known = known_settings(kind)
    else:
        known = [
            f for f in registry[kind].__dataclass_fields__ if not (kind == "ar" and f == "zeros")
        ]
    unknown = [key for key in table if key not in known]
    if unknown:
        raise ValueError(
            f"Unknown field {unknown[0]!r} in [{name}] for kind {kind!r}; known fields: "
            f"kind, {', '.join(sorted(known))}."
        )


def _table(value, name, allowed) -> dict:
    if not isinstance(value, Mapping):
        hint = _meant(name, value)
        raise ValueError(
            f"Spec field {name!r} must be a table{hint}{'' if hint[-1:] == '?' else '.'}"
        )
    if allowed is not None:
        unknown = [key for key in value if key not in allowed]
        if unknown:
            raise ValueError(
                f"Unknown field {unknown[0]!r} in [{name}]; known fields: {', '.join(allowed)}."
            )
    return dict(value)
