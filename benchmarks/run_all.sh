#!/usr/bin/env bash
# Regenerate results/ with the committed commands, one after another (never two
# benchmarks at once: timings would be wrong; `loop` and `stability` run two of their
# loops at once, as their committed tables were made). Every command of
# results/README.md's table is here, in the step its row names
# (tests/test_results_listing.py checks both ways). The whole run has not been
# timed in one go. Its steps, each run on a clean clone on 2026-11-28 (the commits that
# regenerated them say how long), took about 2 h 45 min together on a 2-core machine
# (avx512), two thirds of it in the three test steps (about 32 min), `loop` with
# `speed_damper` and `nonlinear` (25), `noise` (20), `stability` (17, two loops at a
# time) and `general` (16).
#   bash benchmarks/run_all.sh            # every step (the list is printed first)
#   bash benchmarks/run_all.sh sweeps     # only the named steps
#   bash benchmarks/run_all.sh list       # the steps and their commands, nothing run
# The steps in `needs_shared_data` read the shared measured records: ../shared/data/brfd
# (or $BRFD_DATA) and, for `nonlinear`, ../shared/data/nonlinear_benchmarks (or
# $NLB_DATA); where a selected step's folder is missing, nothing is run.
set -euo pipefail
cd "$(dirname "$0")/.."
export JAXCASCADE_CACHE=${JAXCASCADE_CACHE:-off}   # compile times reported cold
needs_shared_data=(loop stability backlash inputs nonlinear declared general_brfd speed_damper)
shared_data() {  # the shared folder a step reads
    case $1 in
        nonlinear|declared) echo "${NLB_DATA:-../shared/data/nonlinear_benchmarks}" ;;
        *) echo "${BRFD_DATA:-../shared/data/brfd}" ;;
    esac
}

bench() {  # issue 6: throughput vs NumPy/SciPy and the FLOP floor; scaling
    jaxcascade bench --out results/bench.csv --json > results/bench.json
    python benchmarks/bench_history.py results/bench.json   # a row in results/bench_history.csv
    jaxcascade bench --backend xla --out results/bench_xla.csv --json > results/bench_xla.json
    python benchmarks/scaling.py --out results/scaling.csv
}
profile() {  # issue 22: the literal iteration's stages, before (71498f6, from a temporary
    # worktree that the script adds and removes) and after (this checkout), one sitting
    python benchmarks/profile_literal.py --rounds 10 --commit 71498f6 \
        --out results/profile_literal_before.md
    PYTHONPATH=. python benchmarks/profile_literal.py --rounds 10 \
        --out results/profile_literal_after.md
}
bench_robust() {  # issue 16: robust on example1, example2 and the random family, 256 records each
    python benchmarks/bench_robust.py --out results/bench_robust
    python benchmarks/compile_options.py --out results/compile_options
}
speed() {  # issue 33: where a loop's and a fit's time goes, cold and warm cache, per stage
    python benchmarks/loop_speed.py --out results/loop_speed
    # a program per candidate structure against one program holding every effect
    python benchmarks/effect_programs.py --out results/effect_programs
}
speed_damper() {  # issue 33: the same for one damper run (loop_speed.brfd_argv), cold and warm
    python benchmarks/loop_speed.py --brfd "${BRFD_DATA:-../shared/data/brfd}" --cases brfd \
        --out results/loop_speed_brfd
}
distributed() {  # issue 7: in-process vs 1 and 2 local Dask workers
    python benchmarks/distributed_throughput.py --realisations 2048 --n 2000 --workers 1,2 \
        --out results/distributed_throughput.csv
}
robust() {  # issue 4: literal vs robust, 100 realisations per cell,
    # and a replicate on fresh records (seed 1); the scripts resume, so old tables go first
    rm -rf results/robust_vs_literal results/robust_vs_literal_seed1
    python benchmarks/robust_vs_literal.py --realisations 100 --chunk-size 8 --quiet \
        --out results/robust_vs_literal
    python benchmarks/robust_vs_literal.py --realisations 100 --chunk-size 8 --seed 1 --quiet \
        --out results/robust_vs_literal_seed1
    python benchmarks/random_family_misses.py results/robust_vs_literal/random.parquet \
        results/robust_vs_literal_seed1/random.parquet --out results/random_family_misses.csv
}
sweeps() {  # issue 3: SNR x N sweeps of both paper examples, 500 realisations per cell
    rm -rf results/sweep_example{1,2}{,_paper}.parquet{,.partial} results/sweep_example{1,2}
    for ex in 1 2; do
        jaxcascade sweep --example $ex --snr 10,25,50 --n 500,1000,4000 --realisations 500 \
            --seed 0 --out results/sweep_example$ex.parquet --plots results/sweep_example$ex
    done
    jaxcascade sweep --example 2 --snr 25 --n 2000 --realisations 500 --seed 0 \
        --out results/sweep_example2_paper.parquet
}
literal() {  # issue 11: the paper's iteration under each reading of its first step
    rm -rf results/literal_readings
    python benchmarks/literal_readings.py --quiet --out results/literal_readings
    rm -rf results/literal_criterion
    python benchmarks/literal_criterion.py --out results/literal_criterion
}
efficiency() {  # issue 13: literal and robust against the Cramer-Rao bound
    rm -rf results/efficiency
    python benchmarks/efficiency.py --realisations 100 --out results/efficiency
}
effects_loop() {  # issue 5: the loop on records with one undeclared effect each;
    # issue 32: how often it adds an effect to a clean record (50 seeds, two lengths)
    python benchmarks/effects_loop.py --out results/effects_loop --seed 1
    python benchmarks/false_additions.py --seeds 50 --n 1024,2000 --out results/false_additions
    # issue 67: --integrate auto on an axis under feedback with friction (8 seeds)
    python benchmarks/axis_integration.py --out results/axis_integration
}
outliers() {  # issue 68, item 5: isolated outliers on clean records (false alarms, 500
    # seeds) and on records with four spikes (the estimates against the clean record's)
    python benchmarks/outliers.py --seeds 500 --spiked 10 --out results/outliers
}
loop() {  # issue 21 (needs ../shared/data): the loop on the measured friction-damper
    # records; brfd.py runs every loop again, so old reports go first
    rm -rf results/brfd
    python benchmarks/brfd.py --data "${BRFD_DATA:-../shared/data/brfd}" --out results/brfd --decimate 16 \
        --init-samples 50 --max-effects 2 --all-records --jobs 2 \
        --effects backlash_friction,backlash_friction_contacts,slack_friction,prandtl_ishlinskii,dahl_friction,output_offset,colored_noise
    # issue 32: each run's model on the records it was not estimated on
    python benchmarks/brfd_amplitude.py --data "${BRFD_DATA:-../shared/data/brfd}" --runs results/brfd \
        --out results/brfd/amplitude
    # issue 32, point 5: what a rule that scores candidates on an amplitude hold-out
    # would see (each hysteresis effect alone, the 30 lb tests at 1.5 in held out)
    python benchmarks/brfd_amplitude_holdout.py --data "${BRFD_DATA:-../shared/data/brfd}" \
        --out results/brfd/amplitude_holdout --decimate 16 --jobs 1
}
stability() {  # issue 21, point 3 (needs ../shared/data): the loop's decision with
    # retries 0/2 x seeds 0-2, both directions, and the four main runs again; two loops at
    # a time (--jobs 2: their wall times in resources.csv overlap); old reports go first
    rm -rf results/brfd_stability
    python benchmarks/brfd.py --data "${BRFD_DATA:-../shared/data/brfd}" --out results/brfd_stability \
        --decimate 16 --init-samples 50 --max-effects 2 --stability --jobs 2 \
        --effects backlash_friction,backlash_friction_contacts,slack_friction,prandtl_ishlinskii,dahl_friction,output_offset,colored_noise
}
backlash() {  # issues 15 and 21 (needs ../shared/data): each hysteresis effect alone on
    # the damper (effects.md); the fitted backlash_friction initialised from 50/20/100
    # samples (initial_state.md)
    python benchmarks/brfd_effect.py --data "${BRFD_DATA:-../shared/data/brfd}" --decimate 16 \
        --effects backlash_friction,backlash_friction_contacts,slack_friction,prandtl_ishlinskii,dahl_friction \
        --out results/brfd_backlash/effects.md
    python benchmarks/brfd_initial_state.py --data "${BRFD_DATA:-../shared/data/brfd}" --decimate 16 \
        --n 50,20,100 --effect backlash_friction --out results/brfd_backlash/initial_state.md
}
reproduce() {  # issue 2: the paper's examples; issue 39: the general backlash's
    for ex in 1 2 general1 general2; do for snr in 25 inf; do for est in literal robust; do
        jaxcascade reproduce --example $ex --snr $snr --estimator $est --out results/reproduce \
            > /dev/null
    done; done; done
}
recursive() {  # issue 25: the recursive estimator: speed, noise-free, vs batch, tracking
    jaxcascade bench --estimator recursive --out results/bench_recursive.csv --json \
        > results/bench_recursive.json
    python benchmarks/recursive_noise_free.py --out results/recursive_noise_free
    python benchmarks/recursive_vs_batch.py --seed 1000 --out results/recursive_vs_batch
    python benchmarks/recursive_tracking.py --out results/recursive_tracking
}
inputs() {  # issue 24 (needs ../shared/data): input designs at equal power (the file
    # input is the shared damper's Kocaeli displacement); the script resumes from its
    # per-cell tables, so old tables go first
    rm -rf results/input_design
    python benchmarks/input_design.py --realisations 200 --data "${BRFD_DATA:-../shared/data/brfd}" \
        --out results/input_design
}
noise() {  # issue 24: pem under AR(1) noise drawn by the script; the noise study
    python benchmarks/pem_coloured.py --realisations 200 --estimators pem,robust \
        --out results/pem_coloured
    rm -rf results/noise_study   # per-cell tables: the script resumes from them
    python benchmarks/noise_study.py --realisations 200 --out results/noise_study
}
nonlinear() {  # issue 32 (needs ../shared/data): the loop on the community's nonlinear
    # benchmarks (the shared MAT files); the script skips finished runs, so old reports go first
    rm -rf results/nonlinear_benchmarks
    # models outside the loop built for EMPS's drift: the README's sentence on EMPS reads them
    python benchmarks/emps_reference.py --data "${NLB_DATA:-../shared/data/nonlinear_benchmarks}" \
        --out results/nonlinear_benchmarks/emps_reference
    # how EMPS's validation record ranks the loop's candidates against its test record
    python benchmarks/emps_candidates.py --data "${NLB_DATA:-../shared/data/nonlinear_benchmarks}" \
        --out results/nonlinear_benchmarks/emps_candidates
    python benchmarks/nonlinear_benchmarks.py --data "${NLB_DATA:-../shared/data/nonlinear_benchmarks}" \
        --out results/nonlinear_benchmarks
}
stand_ins() {  # issue 32: the loop on simulated stand-ins for the two benchmarks not shared
    # (Cascaded_Tanks, WienerHammerBenchMark) in their distributed layouts
    rm -rf results/nonlinear_benchmarks_stand_ins
    python benchmarks/stand_in_benchmarks.py --seed 0 --out results/nonlinear_benchmarks_stand_ins
}
declared() {  # issue 32 (needs ../shared/data): the loop's declared cascade against a refit
    # from the linear model inside its class, on the benchmarks and the tank stand-in
    python benchmarks/declared_start.py --data "${NLB_DATA:-../shared/data/nonlinear_benchmarks}" \
        --out results/declared_start
}
general_brfd() {  # issue 39, point 5 (needs ../shared/data): the damper's loop, both
    # directions, with the curved backlash among the candidates of results/brfd
    rm -rf results/general_backlash/brfd
    python benchmarks/brfd.py --data "${BRFD_DATA:-../shared/data/brfd}" --out results/general_backlash/brfd \
        --decimate 16 --init-samples 50 --max-effects 2 --only harmonics+ --jobs 2 \
        --effects backlash_friction,backlash_friction_contacts,slack_friction,prandtl_ishlinskii,dahl_friction,output_offset,colored_noise,general_backlash
}
statuses() {  # issue 35: every estimator's statuses against the truth
    python benchmarks/status_honesty.py --realisations 100 --seed 0
}
general() {  # issue 39: the general-backlash examples' branches on their records, their
    # output-error estimate and the key-term iteration, noise-free and under noise; the
    # loop's effect
    python benchmarks/general_backlash.py --seed 0 --records 20 --out results/general_backlash
    # the estimators over SNR and N under white noise, and under AR(1) noise at one cell
    python benchmarks/general_backlash_study.py --examples general1,general2 --snr 10,25,50 \
        --n 1000,4000 --records 50 --seed 0 --out results/general_backlash/study
    python benchmarks/general_backlash_study.py --examples general1,general2 --snr 25 \
        --n 4000 --noise ar:0.8 --records 50 --seed 0 --out results/general_backlash/study_coloured
    # the branch degree in the orders: general1 through the Monte-Carlo engine, batched
    jaxcascade sweep --example general1 --snr 25 --n 4000 --realisations 50 \
        --estimator literal,robust,pem --seed 0 --chunk-size 25 \
        --out results/general_backlash/sweep_general1.parquet --overwrite
    # the loop's general_backlash effect on curved and straight records
    python benchmarks/general_backlash_loop.py --seeds 10 --out results/general_backlash/loop
}

slow_tests() {  # issue 40: the slow test set, run and recorded per test (its tests of the shared
    # records, the benchmarks and the damper, skip where ../shared/data is missing)
    python benchmarks/slow_tests.py --out results/slow_tests
}
default_tests() {  # issue 40: the default test run's time, test by test (against ~8 minutes)
    python benchmarks/slow_tests.py --select default --out results/default_tests
}
profile_tests() {  # issues 40, 33: the default run's time by test file and by program
    python benchmarks/default_run_profile.py --out results/default_run_profile
}
mutations() {  # issue 40: each deleted body (an effect, pem's iteration, robust's multi-start)
    # against the default-run tests that must catch it
    python benchmarks/mutation_check.py --out results/mutation_check
}
gpu() {  # issue 69: literal, robust, recursive and the 12-cell sweep on a GPU and on the same
    # machine's CPU in one sitting (results/gpu.{csv,md}); where no GPU is found it says it
    # skipped. Run by name (`bash benchmarks/run_all.sh gpu`): it joins `all` and
    # results/README.md's table once results/gpu.{csv,md} come from a GPU machine
    # (tests/test_results_listing.py holds the table's files to the tracked ones)
    bash benchmarks/gpu.sh
}
all=(bench profile bench_robust speed speed_damper distributed robust sweeps literal efficiency effects_loop outliers loop
    stability backlash reproduce recursive inputs noise nonlinear stand_ins declared statuses general general_brfd
    slow_tests default_tests profile_tests mutations)
needs() {  # whether step $1 reads ../shared/data
    local s
    for s in "${needs_shared_data[@]}"; do [ "$s" = "$1" ] && return 0; done
    return 1
}
steps=("$@")
if [ "${steps[*]}" = list ]; then
    for step in "${all[@]}"; do
        if needs "$step"; then echo "# $step: needs $(shared_data "$step")"; fi
        declare -f "$step"
    done
    exit 0
fi
[ ${#steps[@]} -gt 0 ] || steps=("${all[@]}")
for step in "${steps[@]}"; do
    declare -F "$step" > /dev/null || { echo "run_all.sh: no step '$step' (steps: ${all[*]})" >&2; exit 2; }
    if needs "$step" && [ ! -d "$(shared_data "$step")" ]; then
        echo "run_all.sh: step '$step' needs $(shared_data "$step") (../shared/data); nothing run" >&2
        exit 2
    fi
done
echo "run_all.sh: ${steps[*]}"
for step in "${steps[@]}"; do
    echo "== $step"
    "$step"
done
