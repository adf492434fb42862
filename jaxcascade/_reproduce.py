"""`jaxcascade reproduce`: the paper's examples (placeholder until the figures land)."""
