"""Monte-Carlo sweeps: the spec (`_spec`), the engine that runs chunks of realisations
(`_engine`), resumable runs (`_run`, `_distributed`) and the result tables (`_tables`)."""
