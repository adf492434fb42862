"""What the branch degree (`Orders.degree`, issue 39) must leave unchanged at degree 1:
the Monte-Carlo cell keys of the committed sweeps' specs and the simulated output of
the paper's examples. `tests/data/degree_one_reference.json` holds them as computed by
the package before the degree existed, written by

    git worktree add /tmp/before 65d6a0e
    PYTHONPATH=/tmp/before python tests/degree_one_reference.py tests/data/degree_one_reference.json

and `tests/test_degree.py` computes them again with this checkout.
"""

from __future__ import annotations

import hashlib
import json
import sys


def specs():
    """The specs of the committed sweeps (`benchmarks/run_all.sh`: the examples' SNR x N
    sweeps, the paper's cell, the random family, coloured and heavy-tailed noise, other
    input designs) and explicit parameters."""
    from jaxcascade._montecarlo._spec import Spec

    explicit = {
        "MR1": 1.2, "MR2": -1.4, "DR1": 1.0, "ML1": 0.7, "ML2": -0.8, "DL1": -0.9,
        "a2": 0.15, "b1": -0.2, "b2": 0.35, "cL": 0.2, "mR": 1.2, "cR": 0.3,
    }  # fmt: skip
    grid = dict(snr=(10.0, 25.0, 50.0), n=(500, 1000, 4000))
    return {
        "example1": Spec(example=1, **grid),
        "example2": Spec(example=2, **grid),
        "example2_paper": Spec(example=2, snr=(25.0,), n=(2000,)),
        "random": Spec(family="random", snr=(30.0,), n=(3000,)),
        "random_orders": Spec(family="random", orders="3,2,2,1", snr=(30.0,), n=(3000,)),
        "explicit": Spec(params=explicit, snr=(25.0,), n=(4000,)),
        "ar": Spec(example=1, noise="ar", noise_settings={"poles": [0.8]}, snr=(25.0,), n=(4000,)),
        "student_t": Spec(example=2, noise="student_t", noise_settings={"dof": 3}, n=(2000,)),
        "multisine": Spec(example=1, input="multisine", snr=(25.0,), n=(4000,)),
    }


def reference() -> dict:
    """`{spec: {cell: [key words]}}` and `{example: sha256 of its simulated output}`."""
    import jax
    import numpy as np

    from jaxcascade._system._examples import example
    from jaxcascade._system._simulate import simulate, uniform_input

    keys = {}
    for name, spec in specs().items():
        keys[name] = {
            f"{cell.n}/{cell.snr}": np.asarray(jax.random.key_data(spec.cell_key(cell)))
            .ravel()
            .tolist()
            for cell in spec.cells()
        }
    outputs = {}
    for number in (1, 2):
        u = uniform_input(jax.random.PRNGKey(number), 2000)
        y = np.asarray(simulate(example(number).params(), u))
        outputs[f"example{number}"] = hashlib.sha256(y.tobytes()).hexdigest()
    return {"keys": keys, "outputs": outputs}


if __name__ == "__main__":
    import jax

    jax.config.update("jax_enable_x64", True)
    with open(sys.argv[1], "w") as out:
        json.dump(reference(), out, indent=1, sort_keys=True)
