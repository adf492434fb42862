#!/usr/bin/env bash
# Regenerate everything in results/ with the committed commands, one after another
# (never two benchmarks at once: timings would be wrong). Roughly 45 minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
export JAXCASCADE_CACHE=${JAXCASCADE_CACHE:-off}   # compile times reported cold
# Issue 6: throughput vs the NumPy/SciPy baseline and the FLOP floor; scaling.
jaxcascade bench --out results/bench.csv --json > results/bench.json
python benchmarks/scaling.py --out results/scaling.csv
# Issue 7: sweep throughput in-process vs 1 and 2 local Dask workers.
python benchmarks/distributed_throughput.py --realisations 2048 --n 2000 --workers 1,2 \
    --out results/distributed_throughput.csv
# Issue 4: literal vs robust (100 realisations per cell; robust is ~1 s per fit here).
python benchmarks/robust_vs_literal.py --realisations 100 --chunk-size 8 --quiet \
    --out results/robust_vs_literal
# Issue 3: SNR x N sweeps of both paper examples, 500 realisations per cell.
for ex in 1 2; do
    jaxcascade sweep --example $ex --snr 10,25,50 --n 500,1000,4000 --realisations 500 \
        --seed 0 --out results/sweep_example$ex.parquet --plots results/sweep_example$ex
done
# Issue 5: the model-error loop on the measured friction-damper records.
bash benchmarks/brfd_loop.sh
# Issue 2: the paper's examples.
for ex in 1 2; do for snr in 25 inf; do for est in literal robust; do
    jaxcascade reproduce --example $ex --snr $snr --estimator $est --out results/reproduce > /dev/null
done; done; done
