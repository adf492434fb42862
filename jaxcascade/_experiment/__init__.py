"""What a simulated experiment is made of, beside the system: input designs
(`_inputs/`), noise kinds (`_disturbance/`) and the coloured-noise filters they and the
coloured bounds share (`_noise_filter`), and systems whose parameters change during a
record (`_changing`)."""
