"""The installed package's version (from its metadata, so it is written in one place:
`pyproject.toml`)."""

from __future__ import annotations

import importlib.metadata

try:
    __version__ = importlib.metadata.version("jaxcascade")
except importlib.metadata.PackageNotFoundError:  # run from a source tree, not installed
    __version__ = "0+unknown"
