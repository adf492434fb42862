"""Benchmarks of the batched workload: timing (`_timing`), the NumPy/SciPy baseline
(`_baseline`) and the float64 FLOP floor (`_flops`); the reports `jaxcascade bench`
prints and the CSV row it writes (`_text`)."""
