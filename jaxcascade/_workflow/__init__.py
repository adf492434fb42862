"""Every measured-data command, and the paper's reproduction, as one Python call,
returning a result object.

- `fit_record` (`_fit`, `jaxcascade fit`): a `FitResult`;
- `loop_records`, `loop_benchmark` (`_loop`, `jaxcascade loop`: `loop_command` of one
  `LoopSettings`): a `LoopRun`, whose `report(folder)` writes what `--report` writes
  (`_report`: the files and figures);
- `simulate_model` (`_simulate`, `jaxcascade simulate`): a `Simulation`;
- `reproduce_example` (`_reproduce`, `jaxcascade reproduce`): one simulated record of a
  paper example (or of the general backlash's) fitted, its table and figure written: a
  `Reproduction` (title, status, table, the files written, `to_dict()`).

Each measured-data call takes `Record`s (or arrays with their units) and the command's
defaults (`_defaults`); each result has a short `repr`, the status and warnings the command
prints, and `to_dict()`, the command's JSON. The rules these calls apply live below, in
`_measured/` (the benchmark protocol, integration, scoring, the ARX peer, the schema, the
report's text); this layer composes them and draws the figures (`_plot`), so that the
command line (`_cli/`) only parses, calls and prints.
"""
