"""The measured-data side, "the loop": fit a model to measured records, read its
residual, add the effect the residual points to, and score before and after on records
the fit never saw.

- records of the community benchmarks (`_benchmark_data`); the file readers are
  `jaxcascade._data`, shared with the experiments' file inputs;
- the residual tests (`_diagnose`) and the significance of a gain (`_significance`);
- the effect library, with the hysteresis operators its paths use (`_effects/`), and the
  loop's noise model (`_noise`);
- the initial state (`_initial_state`) and the scores (`_scoring`);
- the ARX peer (`_arx`) and the integrating-plant check (`_integrating`);
- a benchmark's protocol (`_benchmark_protocol`: its split, decimation and test figures);
- the loop (`_loop`), its checkpoint (`_loop_checkpoint`), the saved model
  (`_model_file`), and the synthetic records its tests use (`_testing`);
- the model schema in the records' units (`_schema`) and the report's text (`_report`).

The commands' Python calls (`fit_record`, `loop_records`, `loop_benchmark`,
`simulate_model`) compose these one layer up, in `_workflow/`.
"""
