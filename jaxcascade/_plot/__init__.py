"""Figures (matplotlib's `Figure` API, imported lazily; the user's backend is never
switched): sweeps (`_sweep`), residual tests (`_residuals`), parameter trajectories
(`_trajectory`) and model-error-loop reports (`_loop`)."""
