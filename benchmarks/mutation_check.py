"""Issue 40: deleting the body of pem's iteration, of robust's multi-start or of any one
effect makes the default test run fail. Each deletion is checked on the default-run
tests that should catch it.

    python benchmarks/mutation_check.py [--out results/mutation_check]

For every mutation of `benchmarks/mutation_plugin.py` (every effect of the library, the
structural effects' starts, the contacts variant, the noise model's fit, pem's
iteration, robust's multi-start) it runs `pytest -x` on the named default-run tests with
the mutation applied in the process (`-p mutation_plugin`), and records whether they
failed (the deletion is caught: the default run, which holds these tests, fails) or
passed (it is not). The same tests without a mutation are run first and must pass.
Writes OUT.csv and OUT.md with the commit, date and machine; exits 1 where a mutation
is not caught.
"""

from __future__ import annotations

import argparse
import datetime
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
HERE = pathlib.Path(__file__).resolve().parent

REFERENCES = "tests/test_effect_references.py"


def mutations() -> list[tuple[str, str]]:
    """`(mutation, tests)`: each deletion and the default-run tests that should fail."""
    from jaxcascade._measured._effects import EFFECTS, STRUCTURAL

    rows = [(f"effect:{name}", REFERENCES) for name in EFFECTS if name not in STRUCTURAL]
    loop = "tests/test_loop.py::test_loop_names_the_undeclared_effect_among_rivals"
    rows += [(f"starts:{name}", f"{loop}[{name}]") for name in STRUCTURAL]
    rows.append(("contacts", REFERENCES))
    noise = "tests/test_loop.py::test_loop_names_strongly_coloured_noise_on_the_prediction_error"
    rows.append(("noise", f"{noise}[rivals]"))
    rows.append(("pem", "tests/test_pem.py"))
    rows.append(("robust", "tests/test_robust.py"))
    return rows


PLUGIN = pathlib.Path(tempfile.mkdtemp(prefix="jaxcascade-mutation-"))
shutil.copy(HERE / "mutation_plugin.py", PLUGIN)


def run(mutation: str, tests: str) -> tuple[int, str, float]:
    env = dict(os.environ, JAXCASCADE_MUTATION=mutation)
    # the plugin alone on the path: benchmarks/ there would shadow packages by its
    # scripts' names (nonlinear_benchmarks)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(PLUGIN), env.get("PYTHONPATH")]))
    command = [sys.executable, "-m", "pytest", "-q", "-x", "-n", "0", "-p", "no:cacheprovider"]
    command += ["-p", "mutation_plugin", *tests.split()]
    began = time.perf_counter()
    done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True)
    lines = (done.stdout + done.stderr).strip().splitlines()
    return done.returncode, (lines[-1] if lines else ""), time.perf_counter() - began


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/mutation_check")
    args = parser.parse_args(argv)

    import pandas as pd
    from bench_history import commit
    from loop_speed import machine, markdown

    rows = []
    cases = mutations()
    for tests in sorted({t for _, t in cases}):
        code, summary, seconds = run("", tests)
        if code != 0:
            raise SystemExit(f"mutation_check: {tests} fails without a mutation: {summary}")
    for mutation, tests in cases:
        code, summary, seconds = run(mutation, tests)
        caught = code == 1  # pytest's "tests failed"; other codes are errors of the run
        if code not in (0, 1):
            raise SystemExit(f"mutation_check: {mutation} on {tests}: exit {code}: {summary}")
        rows.append(
            {
                "mutation": mutation,
                "tests": tests,
                "caught": caught,
                "pytest": summary,
                "seconds": round(seconds, 1),
            }
        )
        print(f"{mutation:32s} {'caught' if caught else 'NOT CAUGHT'}  {summary}", flush=True)
    table = pd.DataFrame(rows)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(f"{out}.csv", index=False)
    given = sys.argv[1:] if argv is None else argv
    command = "python benchmarks/mutation_check.py " + " ".join(given)
    date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    missed = int((~table.caught).sum())
    lines = [
        "# Deleted bodies the default test run catches",
        "",
        f"`{command.strip()}`, commit {commit()}, {date}, {machine()}.",
        "",
        "Each row deletes one body at run time (`benchmarks/mutation_plugin.py` says how) and "
        "runs the default-run tests named beside it; `caught`: they failed. The same tests "
        f"pass without a mutation. {len(table) - missed} of {len(table)} caught.",
        "",
        markdown(table),
        "",
    ]
    pathlib.Path(f"{out}.md").write_text("\n".join(lines))
    return 1 if missed else 0


if __name__ == "__main__":
    raise SystemExit(main())
