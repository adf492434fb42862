#!/usr/bin/env bash
# The model-error loop on the measured friction-damper records (issue 5), both ways:
# estimate on one earthquake record, validate on the other. Reads ../shared/data/brfd
# (not copied into the repository); writes results/brfd/<direction>/.
set -euo pipefail
cd "$(dirname "$0")/.."
data=${BRFD_DATA:-../shared/data/brfd}
common=(--input displacement_in --output force_kip --time time_s --decimate 8 --json)
mkdir -p results/brfd
jaxcascade loop "$data/earthquake_kocaeli_dbe.csv" --validate "$data/earthquake_imperialvalley_dbe.csv" \
    "${common[@]}" --report results/brfd/kocaeli_to_imperialvalley > results/brfd/kocaeli_to_imperialvalley.json
jaxcascade loop "$data/earthquake_imperialvalley_dbe.csv" --validate "$data/earthquake_kocaeli_dbe.csv" \
    "${common[@]}" --report results/brfd/imperialvalley_to_kocaeli > results/brfd/imperialvalley_to_kocaeli.json
