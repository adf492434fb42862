"""Issue 33: where a measured-data session's time goes (`jaxcascade loop`, `jaxcascade fit`).

    python benchmarks/loop_speed.py [--out results/loop_speed] [--n 1024] [--repeats 1]
                                    [--brfd ../shared/data/brfd] [--threads N]

Each case runs the CLI in a fresh Python process twice: **cold** with an empty JAX
persistent cache folder (`JAXCASCADE_CACHE`, `XDG_CACHE_HOME`), then **warm** with the
cache the cold run filled (what a user sees the second time). The cases:

- `loop input_delay`: `jaxcascade loop est.csv --validate val.csv` with the default
  settings on the synthetic input-delay records (`jaxcascade._measured._testing.UNDECLARED`,
  Example 1 with a 2-sample input delay, SNR 20, `--n` samples each, seed 0): every
  candidate of the library is fitted.
- `fit`: `jaxcascade fit clean.csv` (robust estimator) on the record of the same input
  and noise without the delay (Example 1 as declared: the fit ends `converged`).
- `loop brfd` (with `--brfd`): one damper run of `benchmarks/brfd.py` (harmonics and the
  Imperial Valley earthquake, validated on Kocaeli, `--decimate 8`, the damper's effect
  list), through the same CLI.

The loop cases run with the CLI's default `--threads` (2 candidates at once on a machine
with two or more cores), or `--threads N`. Inside the process JAX's monitoring events
are summed: programs traced (`jaxpr_trace`),
lowered to StableHLO (`lowering`; `programs` counts them), compiled by XLA or loaded from
the persistent cache (`compile_or_load`: JAX's backend-compile event covers both; of it,
`cache_load` loading the `cache_hits`); `execution_and_host` is the rest of the wall time
(running the programs, NumPy, reading the records, the report). For the loop, each event is also
attributed to the loop's stage it happened in (`declared fit`, `evaluate`, `candidate
fit`, `candidate score`, `standard errors`, `other`). Writes OUT.csv (one row per case
and cache state), OUT_stages.csv and OUT.md with the machine and its load.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import json
import logging
import os
import pathlib
import platform
import re
import subprocess
import sys
import tempfile
import threading
import time

EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "jaxpr_trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lowering",
    "/jax/core/compile/backend_compile_duration": "compile_or_load",
    "/jax/compilation_cache/cache_retrieval_time_sec": "cache_load",
}
# the events that partition a program's preparation (cache loading is inside compiling)
ACCOUNTED = ("jaxpr_trace", "lowering", "compile_or_load")
COUNTS = {
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "programs",
    "/jax/core/compile/backend_compile_duration": "compiled",
    "/jax/compilation_cache/cache_hits": "cache_hits",
}
STAGES = {
    # function of jaxcascade._measured._loop -> the stage its calls belong to
    "evaluate": "evaluate",
    "_fit_candidate": "candidate fit",
    "_fit_noise": "candidate fit",
    "_score_candidate": "candidate score",
    "_score_noise": "candidate score",
    "model_standard_errors": "standard errors",
    "refit": "declared fit",  # outside a candidate's fit: the declared cascade's refinement
}


def child(argv: list[str]) -> dict:
    """Run `jaxcascade ARGV` in this process and return what the events say."""
    import jax

    from jaxcascade._cli import main

    totals: dict[str, float] = {}
    stages: dict[str, dict[str, float]] = {}
    # the stage each thread is in (the loop fits candidates in threads: `--threads`), the
    # intervals of the outermost stage calls, and a lock for the tables
    local = threading.local()
    intervals: list[tuple[float, float]] = []
    lock = threading.Lock()

    def stack():
        if not hasattr(local, "where"):
            local.where = ["other"]
        return local.where

    def add(stage, name, value):
        with lock:
            for table in (totals, stages.setdefault(stage, {})):
                table[name] = table.get(name, 0.0) + value

    def durations(event, seconds, **_):
        if event in EVENTS:
            add(stack()[-1], EVENTS[event], seconds)
        if event in COUNTS:
            add(stack()[-1], COUNTS[event], 1)

    def counts(event, **_):
        if event in COUNTS:
            add(stack()[-1], COUNTS[event], 1)

    jax.monitoring.register_event_duration_secs_listener(durations)
    jax.monitoring.register_event_listener(counts)

    # every program by the name JAX gives it (`jit(name)`), per stage: JAX's compile log
    programs: dict[str, dict[str, float]] = {}

    class Compiles(logging.Handler):
        def emit(self, record):
            message = record.getMessage()
            found = re.match(r"Compiling (\S+) with global shapes", message)
            if found:
                with lock:
                    entry = programs.setdefault(f"{stack()[-1]}|{found.group(1)}", {})
                    entry["programs"] = entry.get("programs", 0) + 1
            found = re.match(r"Finished XLA compilation of (\S+) in ([\d.e+-]+) sec", message)
            if found:
                with lock:
                    entry = programs.setdefault(f"{stack()[-1]}|{found.group(1)}", {})
                    entry["xla_s"] = entry.get("xla_s", 0.0) + float(found.group(2))

    jax.config.update("jax_log_compiles", True)
    logging.getLogger("jax").addHandler(Compiles())

    def staged(function, stage):
        @functools.wraps(function)
        def call(*args, **kwargs):
            where = stack()
            if where[-1] != "other":  # called inside another stage: that stage's time
                return function(*args, **kwargs)
            where.append(stage)
            began = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                where.pop()
                ended = time.perf_counter()
                add(stage, "wall", ended - began)
                with lock:
                    intervals.append((began, ended))

        return call

    if argv[0] == "loop":
        # only the loop's stages are wrapped: importing the loop's modules for another
        # command would add their import time to its process
        from jaxcascade._estimator import _robust
        from jaxcascade._measured import _loop

        for name, stage in STAGES.items():
            setattr(_loop, name, staged(getattr(_loop, name), stage))
        # the declared cascade's robust fit (`Robust.__call__` calls the module's `robust`)
        _robust.robust = staged(_robust.robust, "declared fit")
    began = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(argv)
    wall = time.perf_counter() - began
    stages["other"] = stages.get("other", {})
    # the wall time in which no thread was in a stage (stages in threads overlap)
    staged, end = 0.0, -float("inf")
    for a, b in sorted(intervals):
        staged += max(0.0, b - max(a, end))
        end = max(end, b)
    stages["other"]["wall"] = wall - staged
    threads = None
    if argv[0] == "loop":
        from jaxcascade._measured._loop import default_threads

        given = [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == "--threads"]
        threads = int(given[-1]) if given else default_threads()
    return {
        "code": code,
        "threads": threads,
        "wall": wall,
        "totals": totals,
        "stages": stages,
        "programs": programs,
    }


def run_case(argv: list[str], cache: pathlib.Path) -> dict:
    env = dict(os.environ, JAXCASCADE_CACHE=str(cache / "xla"), XDG_CACHE_HOME=str(cache))
    env.pop("JAX_ENABLE_X64", None)
    began = time.perf_counter()
    done = subprocess.run(
        [sys.executable, __file__, "--child", json.dumps(argv)],
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    process = time.perf_counter() - began
    if done.returncode != 0:
        raise SystemExit(f"loop_speed: {' '.join(argv)} failed:\n{done.stderr[-3000:]}")
    result = json.loads(done.stdout.strip().splitlines()[-1])
    if result["code"] != 0:
        raise SystemExit(f"loop_speed: jaxcascade {' '.join(argv)} exit {result['code']}")
    result["process"] = process
    return result


def records(folder: pathlib.Path, n: int) -> tuple[str, str, str]:
    import jax
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    from jaxcascade._measured._testing import UNDECLARED, undeclared_record

    k_est, k_val = jax.random.split(jax.random.PRNGKey(0))
    paths = []
    for name, key, effect in (
        ("est", k_est, "input_delay"),
        ("val", k_val, "input_delay"),
        ("clean", k_est, None),
    ):
        model, ar = UNDECLARED[effect]()
        u, y = undeclared_record(model, key, n, 20.0, ar)
        path = folder / f"{name}.csv"
        np.savetxt(path, np.column_stack([u, y]), delimiter=",", header="u,y", comments="")
        paths.append(str(path))
    return paths[0], paths[1], paths[2]


BRFD_EFFECTS = (
    "backlash_friction,backlash_friction_contacts,slack_friction,prandtl_ishlinskii,"
    "dahl_friction,output_offset,colored_noise"
)


def brfd_argv(root: str, folder: pathlib.Path) -> list[str]:
    """The damper run `harmonics+imperialvalley_to_kocaeli` of benchmarks/brfd.py at
    `--decimate 8` (its effect list, `--init-samples 50`, `--max-effects 2`) as one
    `jaxcascade loop` command, its report in FOLDER."""
    sys.path.insert(0, str(pathlib.Path(__file__).parent))
    import brfd

    options = argparse.Namespace(
        decimate=8,
        stability=False,
        all_records=False,
        init_samples=50,
        max_effects=2,
        effects=BRFD_EFFECTS,
    )
    run = next(
        r for r in brfd.runs(pathlib.Path(root), options) if r[0].startswith("harmonics+imp")
    )
    return brfd.loop_argv(folder, pathlib.Path(root), options, *run)


def folder_size(folder: pathlib.Path) -> int:
    """Bytes of the files under `folder` (0 where it does not exist)."""
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def markdown(frame) -> str:
    """A pipe table of `frame` (no optional dependency)."""
    columns = [str(c) for c in frame.columns]
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for row in frame.itertuples(index=False):
        cells = ["-" if str(v) == "<NA>" else str(v) for v in row]  # a missing value
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def machine() -> str:
    """The CPU in words (the package's own description) and its widest vector unit."""
    from jaxcascade._benchmark._timing import device_description

    try:
        flags = pathlib.Path("/proc/cpuinfo").read_text()
    except OSError:
        flags = ""
    avx = "avx512" if "avx512f" in flags else ("avx2" if "avx2" in flags else "no avx2")
    return f"{device_description()}, {avx}, Python {platform.python_version()}"


def _by_name(programs, top: int = 25):
    """The cold loop's programs summed by name, the most numerous first (`top` rows and
    one row for the rest)."""
    import pandas as pd

    if programs.empty:
        return programs
    loops = [case for case in programs.case.unique() if case.startswith("loop")]
    if not loops:
        return programs.iloc[:0]
    cold = programs[(programs.case == loops[0]) & (programs.cache == "cold")]
    cold = cold[cold.repeat == cold.repeat.min()]
    table = (
        cold.groupby("program", as_index=False)[["programs", "xla_compile_s"]]
        .sum()
        .sort_values(["programs", "xla_compile_s"], ascending=False)
    )
    stages = cold.groupby("program")["stage"].agg(lambda s: ", ".join(sorted(set(s))))
    table["stages"] = table.program.map(stages)
    if len(table) > top:
        rest = table.iloc[top:]
        table = pd.concat(
            [
                table.iloc[:top],
                pd.DataFrame(
                    [
                        {
                            "program": f"{len(rest)} others",
                            "programs": int(rest.programs.sum()),
                            "xla_compile_s": round(float(rest.xla_compile_s.sum()), 2),
                            "stages": "-",
                        }
                    ]
                ),
            ]
        )
    table["xla_compile_s"] = table.xla_compile_s.round(2)
    # as code: a name such as `jit(<lambda>)` is not HTML in the docs
    table["program"] = [name if name.endswith(" others") else f"`{name}`" for name in table.program]
    return table


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/loop_speed")
    parser.add_argument("--n", type=int, default=1024)
    parser.add_argument("--repeats", type=int, default=1, help="cold/warm pairs per case")
    parser.add_argument("--brfd", default=None, help="../shared/data/brfd: add the damper run")
    parser.add_argument(
        "--cases",
        default=None,
        help="comma-separated cases to run among input_delay, fit and brfd (default: "
        "input_delay and fit, and brfd where --brfd is given)",
    )
    parser.add_argument(
        "--threads",
        type=int,
        default=None,
        help="the loop cases' --threads (default: the CLI's default, 2 on two or more cores)",
    )
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child is not None:
        print(json.dumps(child(json.loads(args.child))))
        return 0

    import jax
    import pandas as pd

    import jaxcascade

    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rows, stage_rows, program_rows = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        folder = pathlib.Path(tmp)
        est, val, clean = records(folder, args.n)
        cases = {
            "loop input_delay": ["loop", est, "--validate", val, "--input", "u", "--output", "y"],
            "fit": ["fit", clean, "--input", "u", "--output", "y"],
        }
        if args.brfd:
            cases["loop brfd"] = brfd_argv(args.brfd, folder / "brfd")
        if args.threads is not None:
            for name, cli in cases.items():
                if cli[0] == "loop":
                    cases[name] = [*cli, "--threads", str(args.threads)]
        if args.cases:
            keep = {f"loop {c}" if c != "fit" else c for c in args.cases.split(",")}
            unknown = keep - set(cases)
            if unknown:
                parser.error(f"--cases: unknown or without its data: {sorted(unknown)}")
            cases = {name: cli for name, cli in cases.items() if name in keep}
        load = os.getloadavg()[0]
        for repeat in range(args.repeats):
            for case, cli in cases.items():
                cache = folder / f"cache-{case.replace(' ', '_')}-{repeat}"
                for state in ("cold", "warm"):
                    result = run_case(cli, cache)
                    t = result["totals"]
                    accounted = sum(t.get(k, 0.0) for k in ACCOUNTED)
                    row = {
                        "case": case,
                        "cache": state,
                        "repeat": repeat,
                        "process_s": round(result["process"], 2),
                        "threads": result["threads"],
                        "command_s": round(result["wall"], 2),
                        "programs": int(t.get("programs", 0)),
                        "compiled": int(t.get("compiled", 0)),
                        "cache_hits": int(t.get("cache_hits", 0)),
                        **{f"{k}_s": round(t.get(k, 0.0), 2) for k in EVENTS.values()},
                        "execution_and_host_s": round(max(0.0, result["wall"] - accounted), 2),
                        "cache_folder_mb": round(folder_size(cache) / 2**20, 1),
                    }
                    rows.append(row)
                    print(row, flush=True)
                    for key, values in result["programs"].items():
                        stage, name = key.split("|", 1)
                        program_rows.append(
                            {
                                "case": case,
                                "cache": state,
                                "repeat": repeat,
                                "stage": stage,
                                "program": name,
                                "programs": int(values.get("programs", 0)),
                                "xla_compile_s": round(values.get("xla_s", 0.0), 2),
                            }
                        )
                    for stage, values in result["stages"].items():
                        stage_rows.append(
                            {
                                "case": case,
                                "cache": state,
                                "repeat": repeat,
                                "stage": stage,
                                "wall_s": round(values.get("wall", 0.0), 2),
                                "programs": int(values.get("programs", 0)),
                                "compiled": int(values.get("compiled", 0)),
                                **{f"{k}_s": round(values.get(k, 0.0), 2) for k in EVENTS.values()},
                            }
                        )
    table = pd.DataFrame(rows)
    table["threads"] = table["threads"].astype("Int64")  # none for `fit`
    stages = pd.DataFrame(stage_rows)
    table.to_csv(out.with_suffix(".csv"), index=False)
    stages.to_csv(out.parent / f"{out.name}_stages.csv", index=False)
    program_table = pd.DataFrame(program_rows)
    program_table.to_csv(out.parent / f"{out.name}_programs.csv", index=False)
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    lines = [
        "# Where a measured-data session's time goes",
        "",
        f"`python benchmarks/loop_speed.py --n {args.n} --repeats {args.repeats}"
        + (f" --brfd {args.brfd}" if args.brfd else "")
        + (f" --cases {args.cases}" if args.cases else "")
        + (f" --threads {args.threads}" if args.threads is not None else "")
        + f"`, commit {commit or 'unknown'}, jaxcascade {jaxcascade.__version__}, "
        f"jax {jax.__version__}; {machine()}; load average {load:.2f} at the start.",
        "",
        "Each case in a fresh process: cold (empty persistent cache), then warm (the cache "
        "the cold run filled). Seconds. `programs`: programs traced and lowered (in every "
        "process, cached or not); `compiled`: programs handed to XLA, compiled or loaded; "
        "`compile_or_load`: XLA compiling them or loading them "
        "from the persistent cache (`cache_hits` loaded, in `cache_load_s`; the CLI keeps "
        "every program in the cache, however quickly it compiled); "
        "`execution_and_host`: the rest of the command's wall time; `threads`: the loop's "
        "`--threads` (candidates fitted at once; the CLI's default is 2 on two or more cores): "
        "with 2 the events' seconds are summed over both threads and overlap each other and "
        "the execution, `execution_and_host` is then the wall time less them, at least 0, "
        "and each stage's `wall_s` below sums its calls' time over the threads (`other`: "
        "the wall time in which no thread was in a stage); `cache_folder_mb`: the "
        "cache folder after the run; `process`: the whole "
        "process, Python's start and imports included. On a cold run the tracing that "
        "`jax.export` does for the kept programs (`_compile.exported`) sends no trace "
        "event and is counted in `execution_and_host`.",
        "",
        markdown(table),
        "",
        "## Per stage of the loop",
        "",
        markdown(stages[stages.case.str.startswith("loop")]),
        "",
        "## The cold loop's programs by name"
        + (f" ({loops[0]})" if (loops := [c for c in cases if c.startswith("loop")]) else ""),
        "",
        "Each program as JAX names it (`jit(function)`, from JAX's compile log), summed "
        "over the loop's stages: how many were lowered and XLA's compile seconds "
        "(`*_programs.csv` has every case, cache state and stage). A program per "
        "model structure, record bucket or start count shows here as a count above 1.",
        "",
        markdown(_by_name(program_table)),
        "",
    ]
    out.with_suffix(".md").write_text("\n".join(lines))
    print(f"wrote {out.with_suffix('.md')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
