"""Issue 67: how EMPS's validation record ranks the loop's candidates against the test.

    python benchmarks/emps_candidates.py [--data ../shared/data/nonlinear_benchmarks]
        [--out results/nonlinear_benchmarks/emps_candidates]

The loop chooses among its candidates by their free-run error on the validation record
(the training record's last quarter, `_benchmark_protocol.BENCHMARK_RULE`). EMPS's output
is a position that integrates the modelled velocity, and its test record is four times
as long as that validation record. This script runs the loop on EMPS with its default
settings (`jc.loop_benchmark`, as `jaxcascade loop --benchmark EMPS` runs it) and scores
every model the loop fitted (the declared cascade, the linear output-error floor, each
round's candidates, the final model) three ways, each as the report scores a record
(`_scoring.score_record`: the state set from the measured output on the `init_samples`
before the scored ones, the position integrated back from the modelled velocity):

- `validation_nrmse`: on the validation record (what the loop decided by);
- `training_mm`: on the whole training record, estimation and validation records
  joined in order (EMPS has one training record), one free run from its start: a horizon
  as long as the test's, three quarters of it in sample;
- `test_mm`: on the official test record (RMSE in mm, the benchmark's figure).

Prints and writes OUT.csv (one row a model) and OUT.md with Spearman's rank correlation
of each of the first two with the test figure over the candidates, the command, machine,
commit and date. About three minutes on the 2-core machine.
"""

from __future__ import annotations

import argparse
import datetime
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).parent))
import bench_history  # noqa: E402
import loop_speed  # noqa: E402


def scorer(run):
    """`score(model, u, y) -> (rmse in the record's unit, nrmse)` on one record in
    model units, the loop's way (integrated back where the loop integrated)."""
    from jaxcascade._measured._integrating import integrated
    from jaxcascade._measured._loop import initialised_output, simulated_output
    from jaxcascade._measured._scoring import score_record

    def score(model, u, y):
        pair = (
            lambda u_: simulated_output(model, u_),
            lambda u_, y_, start, n: initialised_output(model, u_, y_, start, n),
        )
        if run.integrating is not None:
            pair = integrated(*pair)
        s = score_record("model", "record", "scored", u, y, *pair, None, run.init_samples)
        return s.rmse * run.scaling.y_scale, s.error

    return score


def ranking(table):
    """`(candidates, rho_validation, rho_training)`: the rows of OUT.csv's `table` that
    are candidates (round 1 on) with every figure finite, and Spearman's rank correlation
    of their validation NRMSE and of their whole training record's RMSE with their test
    RMSE."""
    import scipy.stats

    scored = ["validation_nrmse", "training_mm", "test_mm"]
    candidates = table[table["round"] > 0]
    finite = candidates[np.isfinite(candidates[scored]).all(axis=1)]
    rho_val = scipy.stats.spearmanr(finite["validation_nrmse"], finite["test_mm"]).statistic
    rho_train = scipy.stats.spearmanr(finite["training_mm"], finite["test_mm"]).statistic
    return finite, rho_val, rho_train


def main(argv=None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    import pandas as pd

    import jaxcascade as jc
    from jaxcascade._benchmark._timing import device_description

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default="../shared/data/nonlinear_benchmarks")
    parser.add_argument("--out", default="results/nonlinear_benchmarks/emps_candidates")
    args = parser.parse_args(argv)
    began = time.perf_counter()
    run = jc.loop_benchmark("EMPS", args.data)
    factor = run.benchmark.benchmark.unit_factor  # the file's unit (m) to the benchmark's (mm)
    score = scorer(run)
    validation, test = run.validation[0], run.test[0]
    u_train = np.concatenate([np.asarray(r.u) for r in [*run.estimation, validation]])
    y_train = np.concatenate([np.asarray(r.y) for r in [*run.estimation, validation]])
    result = run.result
    models = [("declared cascade", "-", 0, "-", result.base)]
    if result.floor is not None:
        models.append(("linear output-error floor", "-", 0, "-", result.floor.model))
    models += [
        (c.name, c.label, c.round, c.action, c.model)
        for c in result.candidates
        if c.model is not None
    ]
    models.append(("final model", "-", 0, "-", result.final))
    rows = []
    for name, label, round_, action, model in models:
        _, validation_nrmse = score(model, validation.u, validation.y)
        training, _ = score(model, u_train, y_train)
        test_rmse, _ = score(model, test.u, test.y)
        rows.append(
            {
                "model": name,
                "variant": label,
                "round": round_,
                "action": action,
                "structure": model.structure(),
                "validation_nrmse": validation_nrmse,
                "training_mm": training * factor,
                "test_mm": test_rmse * factor,
            }
        )
        print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out.with_suffix(".csv"), index=False)
    finite, rho_val, rho_train = ranking(table)
    best_val = finite.loc[finite["validation_nrmse"].idxmin()]
    best_test = finite.loc[finite["test_mm"].idxmin()]
    shown = table.copy()
    for column in ("validation_nrmse", "training_mm", "test_mm"):
        shown[column] = shown[column].map(lambda v: f"{v:.4g}")
    commit = bench_history.commit()
    lines = [
        "# EMPS: how the validation record ranks the loop's candidates against the test",
        "",
        f"`python benchmarks/emps_candidates.py --data {args.data}`, commit {commit}, "
        f"{datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds')}, "
        f"{device_description()}, {time.perf_counter() - began:.0f} s.",
        "",
        "Every model the loop fitted with its defaults on EMPS, scored as its report scores "
        "a record (the position integrated back, the state set on the first "
        f"{run.init_samples} samples): `validation_nrmse` on the validation record (what "
        "the loop decided by), `training_mm` on the whole training record in one free run "
        "(three quarters in sample), `test_mm` on the official test record (the script's "
        "docstring).",
        "",
        loop_speed.markdown(shown),
        "",
        f"Over the {len(finite)} candidates: Spearman's rank correlation with the test "
        f"figure {rho_val:.2f} for the validation NRMSE and {rho_train:.2f} for the whole "
        "training record's RMSE. The validation record's best candidate "
        f"(`{best_val['variant']}`, round {best_val['round']}) scores "
        f"{best_val['test_mm']:.3g} mm on the test; the test's best "
        f"(`{best_test['variant']}`, round {best_test['round']}) "
        f"{best_test['test_mm']:.3g} mm, with validation NRMSE "
        f"{best_test['validation_nrmse']:.3g}.",
    ]
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
