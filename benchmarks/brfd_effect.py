"""Issue 15, fast check: one hysteresis effect alone fitted on the measured friction
damper's estimation records, scored on the other design-basis earthquake.

    python benchmarks/brfd_effect.py [--data ../shared/data/brfd] [--decimate 16]
        [--effects backlash_friction,slack_friction] [--out results/brfd/effects.md]

For each effect named (the registry's `fit_records` on the raw force: no cascade) and
both directions (30 lb harmonic tests + Imperial Valley DBE -> Kocaeli DBE, and
30 lb harmonics + Kocaeli -> Imperial Valley): the effect is fitted on the estimation
records, simulated from rest on the validation record from its displacement alone, and
scored by NRMSE on the whole record and on the strong-motion window (`brfd.WINDOWS`).
Same effect settings both ways. Seconds, not the minutes of the full loop
(`benchmarks/brfd.py`). Prints a Markdown table (and writes it with --out).

For the backlash-friction effects a second row starts the rotor where the measured force
at the first sample puts it (`backlash_friction_start`): the information the published
figures use (they use the measured force's sign at every step as well), not a
prediction from the displacement alone.

For `slack_friction` a second row refines its four parameters (threshold, dead-zone
fraction, both plateaus) by output-error Levenberg-Marquardt on the estimation records
(each weighted by 1/length) from the cross-validated grid point: whether the grid's
choice is the least-squares optimum.
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
    parser.add_argument(
        "--effects", default="backlash_friction,backlash_friction_contacts,slack_friction"
    )
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    sys.path.insert(0, str(pathlib.Path(__file__).parent))
    from brfd import FILES, WINDOWS, harmonic_files, load

    from jaxcascade._measured._effects import EFFECTS
    from jaxcascade._measured._effects._operators import backlash_friction, backlash_friction_start
    from jaxcascade._metrics import score

    def refine_slack(effect, records):
        from jaxcascade._estimator._levenberg import least_squares

        us = tuple(jnp.asarray(r[0]) for r in records)
        ys = tuple(jnp.asarray(r[1]) for r in records)
        cls = type(effect)

        def residual(z, args):
            e = cls(*z)
            return jnp.concatenate(
                [(e.parallel(u) - y) / np.sqrt(len(y)) for u, y in zip(us, ys, strict=True)]
            )

        z0 = jnp.asarray(
            [float(v) for v in (effect.threshold, effect.dead, effect.upper, effect.lower)]
        )
        z, *_ = jax.jit(lambda z0: least_squares(residual, z0, None, max_steps=200))(z0)
        return cls(*z)

    data = pathlib.Path(args.data)
    harmonics = [load(p, args.decimate) for p in harmonic_files(data)]
    quakes = {name: load(data / file, args.decimate) for name, file in FILES.items()}
    lines = [
        "| effect | estimation | validation | window NRMSE | NRMSE | seconds | fitted |",
        "|---|---|---|---|---|---|---|",
    ]
    for name in args.effects.split(","):
        cls = EFFECTS[name]
        for train, valid in (("imperialvalley", "kocaeli"), ("kocaeli", "imperialvalley")):
            started = time.perf_counter()
            records = [(u, y, y) for u, y in [*harmonics, quakes[train]]]
            effect, label = cls.fit_records(None, records)
            u, y = quakes[valid]
            predicted = np.asarray(effect.parallel(jnp.asarray(u)))
            a, b = WINDOWS[valid][0] // args.decimate, -(-WINDOWS[valid][1] // args.decimate)
            seconds = time.perf_counter() - started
            lines.append(
                f"| {name} | 30 lb harmonics + {train} | {valid} | "
                f"{score(y[a:b], predicted[a:b]):.3f} | {score(y, predicted):.3f} | "
                f"{seconds:.0f} | {label} |"
            )
            print(lines[-1], flush=True)
            if name == "slack_friction":
                refined = refine_slack(effect, records)
                predicted = np.asarray(refined.parallel(jnp.asarray(u)))
                lines.append(
                    f"| {name}, refined by least squares | 30 lb harmonics + {train} | {valid} | "
                    f"{score(y[a:b], predicted[a:b]):.3f} | {score(y, predicted):.3f} | - | "
                    f"r={float(refined.threshold):.3g}, dead={float(refined.dead):.3g}, "
                    f"levels={float(refined.upper):.3g}/{float(refined.lower):.3g} |"
                )
                print(lines[-1], flush=True)
            if hasattr(cls, "start_fractions"):
                g, k, up, lo, offset = (
                    abs(float(effect.gap)),
                    abs(float(effect.stiffness)),
                    abs(float(effect.upper)),
                    abs(float(effect.lower)),
                    float(effect.offset),
                )
                start = backlash_friction_start(y[0], g, k, offset)
                predicted = offset + np.asarray(
                    backlash_friction(jnp.asarray(u), g, k, up, lo, (start,))
                )
                lines.append(
                    f"| {name}, rotor started from the measured force at t=0 (published "
                    f"information) | 30 lb harmonics + {train} | {valid} | "
                    f"{score(y[a:b], predicted[a:b]):.3f} | {score(y, predicted):.3f} | "
                    f"- | start {start:.2f} of the half-width |"
                )
                print(lines[-1], flush=True)
    command = (
        f"python benchmarks/brfd_effect.py --data {args.data} --decimate {args.decimate} "
        f"--effects {args.effects}" + (f" --out {args.out}" if args.out else "")
    )
    text = "\n".join([f"Command: `{command}`", "", *lines]) + "\n"
    if args.out:
        pathlib.Path(args.out).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
