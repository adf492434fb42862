"""The system: the model orders (`_orders`), the cascade's parameters and their
invariants (`_model`), the checks
every entry point runs on a record (`_validate`), the simulator (`_simulate`), the
general output backlash (`_general_backlash`), the paper's examples (`_examples`) and
the random-system family (`_prior`). Everything else in the package builds on these."""
