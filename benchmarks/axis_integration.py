"""Whether `--integrate auto` sees the integrator of a positioning axis under feedback.

    python benchmarks/axis_integration.py [--seeds 8] [--n 1025] [--snr 30]
        [--out results/axis_integration]

Each record is `jaxcascade._measured._testing.axis_record`: the force and the measured
position of an axis under proportional control with Coulomb and viscous friction
(`INTEGRATING["velocity_friction"]`), estimation and validation records of N samples
with independent references and noise, drawn from seeds 0 to S-1 (`PRNGKey(seed)` split
in two, as `benchmarks/effects_loop.py` draws its records). Coulomb friction biases the
equation-error ARX fit, whose pole may then lie well inside the unit circle; the loop runs
as `jaxcascade loop` does, with its defaults (`jc.loop_records`: `--integrate auto`, every
effect). Writes OUT.csv (one row per record: seed, the ARX peer's largest pole and gain at
zero frequency, how `auto` decided, the declared cascade's validation NRMSE on the output
and on its difference where both were fitted, the effects added, the validation NRMSE
before and after, seconds) and OUT.md, with the command, commit, date and machine.
"""

from __future__ import annotations

import argparse
import datetime
import pathlib
import time


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--n", type=int, default=1025)
    parser.add_argument("--snr", type=float, default=30.0)
    parser.add_argument("--out", default="results/axis_integration")
    args = parser.parse_args(argv)

    import jax
    import pandas as pd
    from bench_history import commit  # the short hash, "-dirty" with package changes

    import jaxcascade as jc
    from jaxcascade._benchmark._timing import device_description
    from jaxcascade._measured._arx import arx_peer
    from jaxcascade._measured._integrating import integrates, static_gain
    from jaxcascade._measured._testing import INTEGRATING, axis_record

    jax.config.update("jax_enable_x64", True)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    rows = []
    for seed in range(args.seeds):
        began = time.perf_counter()
        keys = jax.random.split(jax.random.PRNGKey(seed))
        friction = INTEGRATING["velocity_friction"]
        est, val = (
            jc.record_from_arrays(*axis_record(k, args.n, args.snr, friction)) for k in keys
        )
        arx, unstable = arx_peer(est.u, est.y)
        run = jc.loop_records(est, val)
        leaky = (run.integrating or {}).get("leaky")
        decided = (
            "output"
            if run.integrating is None
            else "difference (validation chose)"
            if leaky
            else "difference (integrator seen)"
        )
        rows.append(
            {
                "seed": seed,
                "arx_pole": float(arx.largest_pole),
                "arx_stable": unstable is None,
                "arx_gain": float(static_gain(arx, est.u, est.y)) if unstable is None else None,
                "integrator_seen": integrates(est.u, est.y) is not None,
                "decided": decided,
                "declared_on_output": None if not leaky else leaky["level_error"],
                "declared_on_difference": None if not leaky else leaky["difference_error"],
                "effects_added": ",".join(run.result.added) or "none",
                "nrmse_before": float(run.result.before.error),
                "nrmse_after": float(run.result.after.error),
                "seconds": time.perf_counter() - began,
            }
        )
        print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    table.to_csv(out.with_suffix(".csv"), index=False)
    command = "python benchmarks/axis_integration.py " + " ".join(
        f"--{k} {v}"
        for k, v in (("seeds", args.seeds), ("n", args.n), ("snr", args.snr), ("out", args.out))
    )

    def cell(value, digits=4):
        return "-" if value is None or value != value else f"{value:.{digits}g}"

    lines = [
        f"# `--integrate auto` on an axis under feedback with friction (N {args.n}, SNR "
        f"{args.snr:g}, seeds 0-{args.seeds - 1})",
        "",
        f"Command: `{command}`; commit {commit()}, "
        f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, {device_description()}, "
        f"{time.perf_counter() - started:.0f} s.",
        "",
        "The ARX peer's largest pole and its gain at zero frequency (times std(y) / std(u)); "
        "`decided`: how `--integrate auto` modelled the record; `declared on output / on "
        "difference`: the declared cascade's validation NRMSE both ways, where the slow pole "
        "with an integrator's gain made the loop fit both; the validation NRMSE (of the "
        "position, initialised) of the declared cascade and of the final model.",
        "",
        "| seed | ARX pole | gain | decided | declared on output | declared on difference "
        "| effects added | NRMSE before | NRMSE after |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        pole = f"{r['arx_pole']:.4f}" + ("" if r["arx_stable"] else " (no stable fit)")
        lines.append(
            f"| {r['seed']} | {pole} | {cell(r['arx_gain'], 3)} | {r['decided']} | "
            f"{cell(r['declared_on_output'])} | {cell(r['declared_on_difference'])} | "
            f"{r['effects_added']} | {cell(r['nrmse_before'])} | {cell(r['nrmse_after'])} |"
        )
    named = int((table["effects_added"] == "velocity_friction").sum())
    lines += [
        "",
        f"{int((table['decided'] != 'output').sum())} of {len(table)} records modelled "
        f"through their difference; {named} of {len(table)} get exactly velocity_friction.",
    ]
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
