"""Issue 21 (1), a check on measured data: the window NRMSE of a fitted friction model
on the other design-basis earthquake, initialised from the n samples before the window
(`_initial_state.scored`) and from rest.

    python benchmarks/brfd_initial_state.py [--data ../shared/data/brfd] [--decimate 16]
        [--n 50[,20,...]] [--effect backlash_friction]
        [--out results/brfd_backlash/initial_state.md]

The model is `benchmarks/brfd_effect.py`'s: the effect alone (`fit_records` on the raw
force of the 30 lb harmonic tests and one earthquake), here as an `ExtendedModel` whose
cascade outputs zero and carries no state (all slopes 0, gaps 0), so that the only state
an initialisation sets is the effect's (the rotor's position). Both directions; one row
per number of initialisation samples `n` (the convention's is 50; the others show how much
the figure depends on it).
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="../shared/data/brfd")
    parser.add_argument("--decimate", type=int, default=16)
    parser.add_argument("--n", default="50", help="comma-separated")
    parser.add_argument("--effect", default="backlash_friction")
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    sys.path.insert(0, str(pathlib.Path(__file__).parent))
    from brfd import FILES, WINDOWS, harmonic_files, load

    from jaxcascade._measured._effects import EFFECTS, ExtendedModel
    from jaxcascade._measured._initial_state import scored
    from jaxcascade._measured._noise import ARNoise
    from jaxcascade._system._model import CascadeParams, Orders

    data = pathlib.Path(args.data)
    harmonics = [load(p, args.decimate) for p in harmonic_files(data)]
    quakes = {name: load(data / file, args.decimate) for name, file in FILES.items()}
    zero = {"MR1": 0.0, "ML1": 0.0, "cL": 0.0, "mR": 1.0, "cR": 0.0}
    cascade = CascadeParams.from_dict(zero, Orders(1, 1, 1, 0))
    cls = EFFECTS[args.effect]
    lines = [
        "| effect | estimation | validation | window | n | window NRMSE initialised | "
        "from rest | one-step NRMSE initialised | from rest | seconds | fitted |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for train, valid in (("imperialvalley", "kocaeli"), ("kocaeli", "imperialvalley")):
        records = [(u, y, y) for u, y in [*harmonics, quakes[train]]]
        effect, label = cls.fit_records(None, records)
        model = ExtendedModel(cascade, (effect,), ARNoise.white())
        u, y = quakes[valid]
        a, b = WINDOWS[valid][0] // args.decimate, -(-WINDOWS[valid][1] // args.decimate)
        for n in (int(v) for v in args.n.split(",")):
            started = time.perf_counter()
            result = scored(model, jnp.asarray(u), jnp.asarray(y), a, b, n=n)
            seconds = time.perf_counter() - started
            lines.append(
                f"| {args.effect} | 30 lb harmonics + {train} | {valid} | {a}:{b} | {n} | "
                f"{result.error:.3f} | {result.error_from_rest:.3f} | "
                f"{result.prediction_error:.3f} | {result.prediction_error_from_rest:.3f} | "
                f"{seconds:.1f} | {label}, offset={float(effect.offset):.3g} |"
            )
            print(lines[-1], flush=True)
    command = (
        f"python benchmarks/brfd_initial_state.py --data {args.data} --decimate "
        f"{args.decimate} --n {args.n} --effect {args.effect}"
        + (f" --out {args.out}" if args.out else "")
    )
    text = "\n".join([f"Command: `{command}`", "", *lines]) + "\n"
    if args.out:
        pathlib.Path(args.out).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
