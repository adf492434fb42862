"""Issue 32: the model-error loop, default settings, on stand-ins for the two benchmarks of
the collection that are not shared here (Cascaded_Tanks, WienerHammerBenchMark).

    python benchmarks/stand_in_benchmarks.py [--out results/nonlinear_benchmarks_stand_ins]
        [--seed 0] [--only Cascaded_Tanks] [--overwrite] [-- LOOP ARGS]

Each stand-in is a simulated system written in the benchmark's distributed layout (its
MAT file, variable names, shapes, sample period and length; the zip marker where the
`nonlinear-benchmarks` loader looks for one) in a temporary folder, then read by
`jc.benchmark_data` and run as `jaxcascade loop --benchmark NAME --data TMP --report
OUT/NAME --json` exactly as `benchmarks/nonlinear_benchmarks.py` runs the shared ones
(fresh process, wall time, peak resident memory, memory mappings, programs compiled).
What they check is what the real files ask of the loop by their form, not the real
systems' figures:

- `Cascaded_Tanks`: two tanks with square-root outflows, the upper one overflowing (part
  of the overflow reaching the lower one), a water-level sensor with noise, clipped to
  its 0-10 V range and quantised to 5 mV, sampled every 4 s; the pump voltage is a
  random-phase multisine between 2.5 and 8.5 V that never crosses zero; 1,024 estimation
  and 1,024 test samples, as the benchmark has.
- `WienerHammerBenchMark`: 188,000 samples at 51.2 kHz: low-pass Gaussian noise through
  a Chebyshev low-pass, a diode-like static curve and an inverse-Chebyshev low-pass, with
  measurement noise (the benchmark's structure); the split keeps 100,000 training and
  78,800 test samples, so the long-record path (`--max-samples`) runs.

The stand-ins' test figures compare the loop's final model with the ARX peer of the same
run; there are no published figures for them. Written as it goes like
`nonlinear_benchmarks.py` (OUT/NAME/resources.json, then OUT/summary.csv and
OUT/README.md).
"""

from __future__ import annotations

import argparse
import pathlib
import shutil
import sys

import numpy as np
import scipy.io
import scipy.signal

sys.path.insert(0, str(pathlib.Path(__file__).parent))

from nonlinear_benchmarks import run_benchmark, write_summary  # noqa: E402

NAMES = ("Cascaded_Tanks", "WienerHammerBenchMark")
# Said where a stand-in's final model misses a linear figure: the system's mechanisms
# (`_benchmark_data.MECHANISMS`, written by `write_summary` where nothing more is known).
WHY: dict[str, str] = {}
PUBLISHED = (
    " There are no published figures for the stand-ins: the published columns are the real"
    " benchmarks' (Champneys et al. 2024, as issue 67 quotes them), for scale only; the"
    " output-error and ARX peers of the same run are the stand-ins' linear figures."
)


def cascaded_tanks(root: pathlib.Path, rng: np.random.Generator) -> None:
    """The Cascaded_Tanks stand-in (module docstring) as CascadedTanksFiles/dataBenchmark.mat."""
    period, n, substeps = 4.0, 1024, 40
    k1, k2, k3, k4 = 0.05, 0.045, 0.045, 0.024

    def multisine(fmax):
        t = np.arange(n) * period
        lines = np.arange(1, int(fmax * n * period)) / (n * period)
        u = sum(np.cos(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) for f in lines)
        return 5.5 + 3.0 * u / np.max(np.abs(u))

    def simulate(u):
        x1 = x2 = 3.0
        h = period / substeps
        y = np.empty(n)
        for t in range(n):
            for _ in range(substeps):
                x1_next = x1 + h * (-k1 * np.sqrt(max(x1, 0.0)) + k4 * u[t])
                spill = max(x1_next - 10.0, 0.0)  # the upper tank overflows
                x2 = max(x2 + h * (k2 * np.sqrt(max(x1, 0.0)) - k3 * np.sqrt(max(x2, 0.0))), 0)
                x2 += 0.5 * spill  # half of the overflow reaches the lower tank
                x1 = min(x1_next, 10.0)
            y[t] = x2
        y = np.clip(y + 0.02 * rng.standard_normal(n), 0.0, 10.0)
        return np.round(y * 200) / 200  # a sensor quantised to 5 mV

    u_est, u_val = multisine(0.0025), multisine(0.0025)
    data = {"uEst": u_est, "yEst": simulate(u_est), "uVal": u_val, "yVal": simulate(u_val)}
    path = root / "Cascaded_Tanks/CascadedTanksFiles/dataBenchmark.mat"
    path.parent.mkdir(parents=True)
    scipy.io.savemat(path, {**{k: v[:, None] for k, v in data.items()}, "Ts": [[period]]})
    (root / "Cascaded_Tanks/CascadedTanksFiles.zip").touch()


def wiener_hammerstein(root: pathlib.Path, rng: np.random.Generator) -> None:
    """The WienerHammerBenchMark stand-in (module docstring) as WienerHammerBenchMark.mat."""
    n, rate = 188_000, 51_200.0
    nyquist = rate / 2
    u = scipy.signal.lfilter(*scipy.signal.butter(6, 10_000 / nyquist), rng.standard_normal(n))
    u = 0.7 * u / np.std(u)
    x = scipy.signal.lfilter(*scipy.signal.cheby1(3, 0.5, 4_400 / nyquist), u)
    w = np.where(x > 0, x, 0.2 * x) + 0.1 * np.tanh(3 * x)  # a diode-like curve
    y = scipy.signal.lfilter(*scipy.signal.cheby2(3, 40, 5_000 / nyquist), w)
    y = y + 0.002 * rng.standard_normal(n)
    path = root / "WienerHammerBenchMark/WienerHammerBenchMark.mat"
    path.parent.mkdir(parents=True)
    scipy.io.savemat(path, {"uBenchMark": u[:, None], "yBenchMark": y[:, None], "fs": [[rate]]})


MAKERS = {"Cascaded_Tanks": cascaded_tanks, "WienerHammerBenchMark": wiener_hammerstein}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="results/nonlinear_benchmarks_stand_ins")
    parser.add_argument("--seed", type=int, default=0, help="the stand-ins' noise and phases")
    parser.add_argument("--only", default=None, help="NAME,NAME of the stand-ins to run")
    parser.add_argument("--overwrite", action="store_true", help="run finished ones again")
    parser.add_argument("extra", nargs="*", help="after --: passed on to jaxcascade loop")
    args = parser.parse_args(argv)
    names = NAMES if args.only is None else tuple(args.only.split(","))
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    title = "The model-error loop on stand-ins for the benchmarks not shared (default settings)"
    written_by = f"`python benchmarks/stand_in_benchmarks.py --seed {args.seed}`"
    for name in names:
        report = out / name
        if (report / "resources.json").exists() and not args.overwrite:
            print(f"{name}: finished earlier ({report}); skipped", file=sys.stderr)
            continue
        # the stand-in's files in a folder of their own beside the reports, removed after
        # the run (the reports name it; nothing of it is kept)
        data = out / "data"
        shutil.rmtree(data, ignore_errors=True)
        try:
            MAKERS[name](data, np.random.default_rng(args.seed))
            stand_in = f"python benchmarks/stand_in_benchmarks.py --seed {args.seed} "
            stand_in += f"({MAKERS[name].__name__})"
            run_benchmark(name, data, report, args.extra, stand_in=stand_in)
        finally:
            shutil.rmtree(data, ignore_errors=True)
        write_summary(out, why=WHY, title=title, written_by=written_by, published=PUBLISHED)
    write_summary(out, why=WHY, title=title, written_by=written_by, published=PUBLISHED)
    return 0


if __name__ == "__main__":
    sys.exit(main())
