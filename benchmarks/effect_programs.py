"""Issue 33: what a program per candidate structure costs to compile, against one
program that holds every effect (the measurement behind the loop's design question).

    python benchmarks/effect_programs.py [--n 1024] [--out results/effect_programs]

The model-error loop compiles its initial-state fit (`_initial_state._initialise`) and
its refit (`_loop._refit`) once per candidate structure: the cascade with one effect of
the library added. For the declared cascade of Example 1 on one record of N samples
(`_testing.undeclared_record`, SNR 20), each case below runs in a fresh process with
JAX's persistent cache off, and compiles both programs as the loop does (the package's
XLA options, `_compile.filter_jit`):

- `cascade`: no effect (the refit adds nothing: the cascade refined alone);
- `<effect>`: that effect alone, added to the cascade (its first start from
  `Effect.starts` on the record's residual; the refit from all its starts, as the loop);
- `all`: every effect that keeps the cascade's orders, stacked in one model (the
  initial-state fit of the model with all of them; the refit of the cascade with all but
  the last, adding the last): the size of one program that would hold them all.

Seconds from JAX's own events (`jax.monitoring`): tracing (`jaxpr_trace_s`), lowering
to StableHLO (`lowering_s`) and XLA's compile (`xla_s`), and one run of the compiled
initial-state program (`run_s`, its second call). Writes OUT.csv and OUT.md, with the
machine and the load. Run it on a quiet machine.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import pathlib
import subprocess
import sys
import time

from jaxcascade._measured._effects import STRUCTURAL
from jaxcascade._names import EFFECTS as LIBRARY_NAMES

# the effects that keep the cascade's orders (`dynamics_order` and `pwl_segment` change
# them; `colored_noise` is the noise model, not an effect)
EFFECTS = tuple(name for name in LIBRARY_NAMES if name not in STRUCTURAL)
EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "jaxpr_trace_s",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lowering_s",
    "/jax/core/compile/backend_compile_duration": "xla_s",
}


def child(case: str, n: int) -> dict:
    """Compile the case's two programs in this process; what the events say."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    from jaxcascade._compile import pad
    from jaxcascade._measured import _loop
    from jaxcascade._measured._effects import EFFECTS as LIBRARY
    from jaxcascade._measured._effects import ExtendedModel, Start, simulate_extended
    from jaxcascade._measured._initial_state import GRID, MAX_STEPS, _initialise
    from jaxcascade._measured._noise import ARNoise
    from jaxcascade._measured._testing import UNDECLARED, undeclared_record

    base, _ = UNDECLARED[None]()
    u, y = undeclared_record(base, jax.random.PRNGKey(0), n, 20.0)
    u, y = np.asarray(u), np.asarray(y)
    residual = y - np.asarray(simulate_extended(base, jnp.asarray(u)))

    def instance(name):
        # effects tried only where the residual shows them (`_feedback.MIN_EXPLAINED`), on
        # an integrating record, or after output_dynamics have no start on this clean
        # record: their synthetic record's values (`_testing`) make the same programs
        if name in UNDECLARED:
            return UNDECLARED[name]()[0].effects[-1]
        values = {
            "velocity_friction": (0.3, 0.4),
            "inner_polynomial": (0.0, 0.15, -0.08),
            "inner_kink": (0.0, 0.5, 0.0),
        }
        return LIBRARY[name](jnp.asarray(values[name])) if name in values else None

    def start(name):
        starts = LIBRARY[name].starts(base, u, y, residual)
        if not starts and instance(name) is not None:
            effect = jax.tree_util.tree_map(
                lambda a: a[None] if eqx.is_array(a) else a, instance(name)
            )
            vector = np.asarray(base.params.to_vector())[None]
            return Start(name, base.orders, vector, effect)
        if not starts or starts[0].orders != base.orders:
            raise RuntimeError(f"{name}: no start that keeps the cascade's orders")
        return starts[0]

    def first(effect):
        return jax.tree_util.tree_map(lambda a: a[0] if eqx.is_array(a) else a, effect)

    names = () if case == "cascade" else (EFFECTS if case == "all" else (case,))
    starts = [start(name) for name in names]
    effects = tuple(first(s.effect) for s in starts)
    model = ExtendedModel(base.params, effects, ARNoise.white())
    # the refit: the cascade with every effect but the last, adding the last
    current = ExtendedModel(base.params, effects[:-1], ARNoise.white())
    added = starts[-1] if starts else _loop._no_effect(base.params)

    totals: dict[str, float] = {}
    phase = ["initial state"]

    def durations(event, seconds, **_):
        if event in EVENTS:
            key = (phase[0], EVENTS[event])
            totals[key] = totals.get(key, 0.0) + seconds

    jax.monitoring.register_event_duration_secs_listener(durations)
    arguments = (model, jnp.asarray(pad(u)), jnp.asarray(pad(y)), jnp.asarray(50, jnp.int32))
    options = {"n": 50, "grid": GRID, "max_steps": MAX_STEPS}
    jax.block_until_ready(_initialise.jitted(*arguments, **options))
    began = time.perf_counter()
    jax.block_until_ready(_initialise.jitted(*arguments, **options))
    run_s = time.perf_counter() - began
    phase[0] = "refit"
    _loop.refit_all(current, added, u, y)
    rows = []
    for program in ("initial state", "refit"):
        row = {"case": case, "effects": len(names), "program": program}
        for name in EVENTS.values():
            row[name] = round(totals.get((program, name), 0.0), 3)
        row["run_s"] = round(run_s, 4) if program == "initial state" else None
        rows.append(row)
    return {"rows": rows}


def run_case(case: str, n: int) -> list[dict]:
    env = {**os.environ, "JAXCASCADE_CACHE": "off"}
    argv = [sys.executable, __file__, "--child", case, "--n", str(n)]
    done = subprocess.run(argv, capture_output=True, text=True, env=env)
    if done.returncode != 0:
        raise RuntimeError(f"{case}: {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])["rows"]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=1024)
    parser.add_argument("--out", default="results/effect_programs")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child, args.n)))
        return 0
    import pandas as pd

    sys.path.insert(0, str(pathlib.Path(__file__).parent))
    from loop_speed import machine, markdown

    import jaxcascade

    load = os.getloadavg()[0]
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    rows = []
    for case in ("cascade", *EFFECTS, "all"):
        rows += run_case(case, args.n)
        print(f"{case}: done", file=sys.stderr)
    frame = pd.DataFrame(rows)
    frame["compile_s"] = (frame.jaxpr_trace_s + frame.lowering_s + frame.xla_s).round(3)
    frame["run_s"] = frame.run_s.astype("Float64")  # none for the refit: "-" in the table
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(out.with_suffix(".csv"), index=False)
    singles = frame[~frame.case.isin(["cascade", "all"])]
    whole = frame[frame.case == "all"]
    summary = []
    for program in ("initial state", "refit"):
        one = singles[singles.program == program]
        together = whole[whole.program == program]
        summary.append(
            {
                "program": program,
                "one per effect: programs": len(one),
                "one per effect: compile s, summed": round(one.compile_s.sum(), 2),
                "one per effect: xla s, summed": round(one.xla_s.sum(), 2),
                "all effects in one: compile s": round(together.compile_s.sum(), 2),
                "all effects in one: xla s": round(together.xla_s.sum(), 2),
            }
        )
    given = sys.argv[1:] if argv is None else list(argv)
    command = " ".join(["python benchmarks/effect_programs.py", *given])
    when = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    text = [
        "# A program per candidate structure against one program with every effect",
        "",
        f"`{command}`, commit {commit}, jaxcascade {jaxcascade.__version__}, {when}; "
        f"{machine()}; load average {load:.2f} at the start.",
        "",
        f"Example 1's declared cascade on one record of {args.n} samples; each case in a "
        "fresh process, JAX's persistent cache off, the package's XLA options. Seconds from "
        "JAX's events: tracing, lowering and XLA's compile (`compile_s` their sum), and one "
        "run of the compiled initial-state fit (`run_s`). `all`: the "
        f"{len(EFFECTS)} effects that keep the cascade's orders in one model (the refit: "
        "the cascade with all but the last, adding the last). Its `run_s` is that model's, "
        "every effect active and a grid of starts for each operator's state: not the run "
        "time of one program that holds every effect with one of them switched on.",
        "",
        "## Summed over the effects, against one model with all of them",
        "",
        markdown(pd.DataFrame(summary)),
        "",
        "## Every case",
        "",
        markdown(frame),
        "",
    ]
    out.with_suffix(".md").write_text("\n".join(text))
    print(out.with_suffix(".md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
