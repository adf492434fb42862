"""What a model-error loop keeps of its work (issue 38): a checkpoint file per finished
fit and round, written as each finishes, so that a killed or interrupted loop continues
where it stopped (`jaxcascade loop --resume`).

The files of one run, in its checkpoint folder (`REPORT/checkpoints/` on the command
line):

- `run.json`: the run's identity (`identity`: the loop's options that change its
  results and the SHA-256 of its records' arrays), written before any fit;
- `declared.json`: the declared cascade's fit;
- `round-RR-ACTION-NAME.json`: one candidate's fitted model and its scores;
- `round-RR.json`: what the round decided;
- `standard-errors.json`: the final model's standard errors.

A model is stored leaf by leaf (`model_to_dict`): dtype, shape and values, a float as
JSON's shortest repr that reads back to the same float64, so a loaded model is the
fitted one bit for bit. Each file is written to a temporary file and renamed
(`os.replace`): a file on disk is whole, whenever the process was killed. A resumed
loop loads the finished fits instead of refitting and scores them again (deterministic
and cheap beside a fit), so its decisions, estimates and errors are those of an
uninterrupted run.

`Checkpoints` also keeps where the loop is (`where`), for the sentence that an
interrupted run ends with; one without a folder keeps only that.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import pathlib
import shutil

import jax
import jax.numpy as jnp
import numpy as np

from .._system._model import CascadeParams, Orders
from ._effects import EFFECTS, Effect, ExtendedModel
from ._noise import ARNoise

# the run's identity, written first: its presence marks a folder of checkpoints
RUN = "run.json"
# layout of the files; a folder of another layout is not resumed
FORMAT = 1


# ---- models as JSON, bit for bit ------------------------------------------------------


def _array_to_dict(leaf) -> dict:
    value = np.asarray(leaf)
    return {
        "dtype": str(value.dtype),
        "shape": list(value.shape),
        "values": value.ravel().tolist(),
        # how the fit held it: a NumPy or a JAX array, JAX's weak type (a Python scalar
        # made into an array), so that the loaded model traces to the same programs
        "jax": isinstance(leaf, jax.Array),
        "weak": bool(getattr(leaf, "weak_type", False)),
    }


def _array_from_dict(data: dict):
    value = np.asarray(data["values"], dtype=data["dtype"]).reshape(data["shape"])
    if not data.get("jax", True):
        return value
    if data.get("weak") and value.shape == ():
        weak = jnp.asarray(value.item())  # weakly typed, as a Python scalar makes it
        if weak.dtype == value.dtype:
            return weak
    return jnp.asarray(value)


def _module_to_dict(module) -> dict:
    return {
        field.name: _array_to_dict(getattr(module, field.name))
        for field in dataclasses.fields(module)
        if not field.metadata.get("static", False)
    }


def _module_from_dict(cls, fields: dict, **static):
    # what equinox does when it unflattens: no `__init__`, no checks (a fitted model was
    # checked, or held unchecked, when it was made)
    module = object.__new__(cls)
    for name, value in fields.items():
        object.__setattr__(module, name, _array_from_dict(value))
    for name, value in static.items():
        object.__setattr__(module, name, value)
    return module


def params_to_dict(params: CascadeParams) -> dict:
    """A cascade's parameters as JSON (every array field, and its orders)."""
    o = params.orders
    return {"orders": [o.nR, o.nL, o.r, o.p], "fields": _module_to_dict(params)}


def params_from_dict(data: dict) -> CascadeParams:
    """Inverse of `params_to_dict`."""
    return _module_from_dict(CascadeParams, data["fields"], orders=Orders(*data["orders"]))


# the classes an effect of a stored model may have: the library's, and the empty effect
# of a refit that adds nothing (`_loop._no_effect`)
_EFFECT_CLASSES = {cls.__name__: cls for cls in (Effect, *EFFECTS.values())}


def model_to_dict(model: ExtendedModel) -> dict:
    """An `ExtendedModel` as JSON: its cascade, each effect by class and fields, its noise
    model, whether it has a cascade; every value in full precision."""
    return {
        "params": params_to_dict(model.params),
        "effects": [
            {"class": type(e).__name__, "fields": _module_to_dict(e)} for e in model.effects
        ],
        "noise": _module_to_dict(model.noise),
        "cascade": bool(model.cascade),
    }


def model_from_dict(data: dict) -> ExtendedModel:
    """Inverse of `model_to_dict`: the same model, leaf for leaf."""
    unknown = [e["class"] for e in data["effects"] if e["class"] not in _EFFECT_CLASSES]
    if unknown:
        raise ValueError(f"a checkpoint holds effect(s) {unknown} that this version lacks.")
    return _module_from_dict(
        ExtendedModel,
        {},
        params=params_from_dict(data["params"]),
        effects=tuple(
            _module_from_dict(_EFFECT_CLASSES[e["class"]], e["fields"]) for e in data["effects"]
        ),
        noise=_module_from_dict(ARNoise, data["noise"]),
        cascade=bool(data["cascade"]),
    )


# ---- a run's identity -----------------------------------------------------------------


def data_hash(arrays) -> str:
    """SHA-256 of a sequence of arrays: each one's dtype, shape and bytes, in order."""
    digest = hashlib.sha256()
    for array in arrays:
        value = np.ascontiguousarray(np.asarray(array))
        digest.update(f"{value.dtype.str}{value.shape}".encode())
        digest.update(value.tobytes())
    return digest.hexdigest()


def identity(arrays, options: dict) -> dict:
    """What must match for a resumed loop to continue the same run: the options that
    change its results (JSON values) and the hash of its records' arrays."""
    return {"format": FORMAT, "options": options, "data_sha256": data_hash(arrays)}


def _differences(stored: dict, expected: dict) -> list[str]:
    expected = json.loads(json.dumps(expected))
    names = []
    if stored.get("format") != expected["format"]:
        names.append("checkpoint format")
    old, new = stored.get("options") or {}, expected["options"]
    names += [key for key in sorted(set(old) | set(new)) if old.get(key) != new.get(key)]
    if stored.get("data_sha256") != expected["data_sha256"]:
        names.append("records")
    return names


# ---- the folder -----------------------------------------------------------------------


class Checkpoints:
    """A run's checkpoint folder (`folder`; `None`: nothing is kept) and where the run is.

    `resume`: continue from the checkpoints in `folder` (starts afresh where it holds
    none); `overwrite`: delete them and start afresh. With neither, a folder that holds
    an earlier run's checkpoints is refused at construction (one sentence, before any
    work); `start` refuses to resume a run of other records or options.
    """

    def __init__(self, folder=None, *, resume: bool = False, overwrite: bool = False):
        if resume and overwrite:
            raise ValueError("give either --resume or --overwrite, not both.")
        self.folder = None if folder is None else pathlib.Path(folder)
        self.resume, self.overwrite = resume, overwrite
        self.loaded = 0  # finished items read back by this run
        self.where: dict = {"stage": "start"}
        if self.held() and not (resume or overwrite):
            raise ValueError(
                f"'{self.folder}' holds the checkpoints of an earlier loop; pass --resume to "
                "continue it, --overwrite to start afresh, or choose another --report."
            )

    def held(self) -> bool:
        """Whether the folder holds a run's checkpoints."""
        return self.folder is not None and (self.folder / RUN).exists()

    def start(self, identity: dict, command: str | None = None) -> int:
        """Open the folder for the run `identity`: continue the one there (`resume`, the
        same identity), or start afresh. Returns how many finished items it holds."""
        if self.folder is None:
            return 0
        if self.held() and self.overwrite:
            shutil.rmtree(self.folder)
        if self.held():
            try:
                stored = json.loads((self.folder / RUN).read_text())
            except (OSError, ValueError):
                stored = {}
            different = _differences(stored, identity)
            if different:
                raise ValueError(
                    f"'{self.folder}' holds the checkpoints of a loop with other "
                    f"{', '.join(different)}; run it with those, or pass --overwrite to "
                    "start afresh."
                )
            return len(self.names())
        self.folder.mkdir(parents=True, exist_ok=True)
        self._write(RUN, {**identity, "command": command})
        return 0

    def names(self) -> list[str]:
        """The finished items on disk (file stems), in name order."""
        if self.folder is None or not self.folder.exists():
            return []
        return sorted(p.stem for p in self.folder.glob("*.json") if p.name != RUN)

    def finished(self) -> list[dict]:
        """One line per finished item, for an interrupted run's report: `item`, and where
        it has them `round`, `label`, `error`, `t`, `significant`, `outcome`."""
        rows = []
        for name in self.names():
            try:
                data = json.loads((self.folder / f"{name}.json").read_text())
            except (OSError, ValueError):
                continue
            row = {"item": name}
            if name == "declared":
                row["label"] = "declared cascade"
            for key in ("round", "label", "outcome"):
                if key in data:
                    row[key] = data[key]
            row.update(data.get("scores") or {})
            rows.append(row)
        return rows

    def load(self, key: str) -> dict | None:
        """The item `key` if it finished (`resume`), else None."""
        if self.folder is None or not self.resume:
            return None
        try:
            data = json.loads((self.folder / f"{key}.json").read_text())
        except (OSError, ValueError):
            return None  # not finished (a temporary file is never read)
        self.loaded += 1
        return data

    def save(self, key: str, payload: dict) -> None:
        """Write the finished item `key` at once, atomically."""
        if self.folder is not None:
            self._write(f"{key}.json", payload)

    def _write(self, name: str, payload: dict) -> None:
        path = self.folder / name
        temporary = path.with_name(f".{name}.{os.getpid()}.tmp")
        temporary.write_text(json.dumps(payload))
        os.replace(temporary, path)

    def remove(self) -> None:
        """Delete the folder (the run finished and its report is written)."""
        if self.folder is not None and self.folder.exists():
            shutil.rmtree(self.folder)

    def at(self, stage: str, **position) -> None:
        """Where the run is now: `stage` and e.g. `round`, `candidate`, `k`, `n`."""
        self.where = {"stage": stage, **position}

    def describe(self) -> str:
        """Where the run is, in words (for an interrupted run's report)."""
        w = self.where
        if w["stage"] == "candidate":
            return f"in round {w['round']}, at candidate {w['k']} of {w['n']} ({w['candidate']})"
        if w["stage"] == "round":
            return f"in round {w['round']}, choosing among its candidates"
        return {
            "start": "before the declared cascade's fit",
            "declared": "while fitting the declared cascade",
            "standard_errors": "while computing the final model's standard errors",
            "report": "after the loop, while scoring and writing the report",
        }.get(w["stage"], w["stage"])
