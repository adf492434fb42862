"""What `jaxcascade bench` prints and writes from a benchmark's record: the text report of
the literal workload (`literal_text`, `_timing.run_benchmark`'s record), of the robust
workload (`robust_text`, `_robust.run_benchmark`'s) and of the recursive estimator
(`recursive_text`, `_recursive.run_benchmark`'s), and the record as a one-row CSV file
(`write_csv`)."""

from __future__ import annotations

import csv
import json
import os
import time


def literal_text(r: dict) -> str:
    """The literal workload's report, one figure a line: the workload, the device,
    jaxcascade's fits per second, the NumPy baseline's and the ratio, the FLOP floor and
    the fraction of it reached, the peak memory and the load average."""
    return "\n".join(
        [
            f"workload: Example {r['example']}, N = {r['n']}, SNR {r['snr']:g}, "
            f"{r['iterations']} iterations, {r['realisations']} realisations ({r['dtype']})",
            f"device: {r['device']}",
            f"jaxcascade ({r['backend']} normal equations, {r['workers']} host thread(s)): "
            f"{r['fits_per_s']:.1f} fits/s "
            f"({r['run_s']:.3f} s per run; compile {r['compile_s']:.2f} s, kernel build "
            f"{r['kernel_build_s']:.2f} s; statuses {r['status_counts']})",
            f"numpy baseline: {r['baseline_fits_per_s']:.2f} fits/s "
            f"({r['baseline_realisations']} realisations in {r['baseline_s']:.2f} s, "
            f"{r['baseline_threads']} BLAS thread(s))",
            f"ratio to baseline: {r['ratio']:.1f}",
            f"floor: {r['flops_per_fit'] / 1e6:.2f} MFlop per fit ({r['floor_count']}) at "
            f"{r['matmul_gflops']:.1f} "
            f"GFlop/s ({r['matmul_backend']} float64 matmul, {r['matmul_size']}^3) = "
            f"{r['floor_fits_per_s']:.0f} fits/s; fraction reached {r['floor_fraction']:.3f}",
            f"peak memory: {r['peak_mem_mb']:.0f} MB (peak RSS after the batched run)",
            f"load average as the timed runs started: {r['load']:.2f}",
        ]
    )


def robust_text(r: dict) -> str:
    """The robust workload's report: the workload, the device, jaxcascade's fits per
    second with the fractions recovered, converged and on the adaptive path, the SciPy
    baseline's fits per second and the ratio."""
    return "\n".join(
        [
            f"workload: {r['estimator']} on {r['system']}, N = {r['n']}, SNR {r['snr']:g}, "
            f"{r['realisations']} realisations",
            f"device: {r['device']}",
            f"jaxcascade: {r['fits_per_s']:.1f} fits/s ({r['run_s']:.2f} s per run; compile "
            f"{r['compile_s']:.2f} s); recovered {r['recovered']:.3f} (converged "
            f"{r['converged']:.3f}, adaptive path {r['adaptive_fraction']:.3f})",
            f"scipy baseline: {r['baseline_fits_per_s']:.3f} fits/s "
            f"({r['baseline_realisations']} realisations in {r['baseline_s']:.1f} s)",
            f"ratio to baseline: {r['ratio']:.1f}",
        ]
    )


def recursive_text(r: dict) -> str:
    """The recursive estimator's report: the workload, the device, sample updates per
    second against the NumPy loop's (with the largest difference of their estimates),
    the ratio and the real-time factor at the record's sample rate."""
    return "\n".join(
        [
            f"workload: recursive over Example {r['example']}, N = {r['n']}, SNR {r['snr']:g}, "
            f"{r['realisations']} records at once",
            f"device: {r['device']}",
            f"jaxcascade: {r['updates_per_s']:.3g} sample updates/s ({r['run_s']:.3f} s per "
            f"run; compile {r['compile_s']:.2f} s; statuses {r['status_counts']})",
            f"numpy loop: {r['baseline_updates_per_s']:.3g} sample updates/s "
            f"({r['baseline_realisations']} records in {r['baseline_s']:.2f} s; largest "
            f"difference of the estimates {r['baseline_max_difference']:.1e})",
            f"ratio to the numpy loop: {r['ratio']:.0f}",
            f"real-time factor at {r['sample_rate_hz']:g} Hz per record: "
            f"{r['real_time_factor']:.0f}",
        ]
    )


def write_csv(record: dict, path: str | os.PathLike) -> None:
    """Write `record` to `path` as a CSV file of one row, its keys the header (the status
    counts as JSON), with the JAX version and the date and time appended."""
    row = {key: value for key, value in record.items() if key != "status_counts"}
    if "status_counts" in record:
        row["status_counts"] = json.dumps(record["status_counts"])
    row["jax_version"] = __import__("jax").__version__
    row["date"] = time.strftime("%Y-%m-%dT%H:%M:%S")
    with open(path, "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(row))
        writer.writeheader()
        writer.writerow(row)
