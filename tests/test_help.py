"""`--help` of the command line: it answers without importing JAX (so at once), every
option says what it does, and the top-level help ends with examples."""

import argparse
import json
import subprocess
import sys

import pytest

from jaxcascade._cli import build_parser

COMMANDS = ("reproduce", "sweep", "fit", "loop", "simulate", "bench")
HEAVY = ("jax", "jaxlib", "numpy", "pandas", "matplotlib", "equinox", "scipy")

# In a fresh interpreter: every command's --help, then the heavy packages imported so far.
PROBE = """
import contextlib, io, json, sys
from jaxcascade._cli import main
texts = {}
for argv in [["--help"]] + [[c, "--help"] for c in %r]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        try:
            main(argv)
        except SystemExit:
            pass
    texts[" ".join(argv)] = out.getvalue()
heavy = sorted({m.split(".")[0] for m in sys.modules} & set(%r))
print(json.dumps({"heavy": heavy, "texts": texts}))
"""


@pytest.fixture(scope="module")
def probe() -> dict:
    code = PROBE % (COMMANDS, HEAVY)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(done.stdout)


def test_help_imports_no_jax_numpy_or_pandas(probe):
    assert probe["heavy"] == []
    assert len(probe["texts"]) == 1 + len(COMMANDS)
    for argv, text in probe["texts"].items():
        assert text.startswith("usage: jaxcascade"), argv
        assert "examples:\n  jaxcascade " in text, argv


VERSION_PROBE = """
import contextlib, io, json, sys
from jaxcascade._cli import main
out = io.StringIO()
with contextlib.redirect_stdout(out):
    try:
        main(["--version"])
        status = None
    except SystemExit as error:
        status = error.code
heavy = sorted({m.split(".")[0] for m in sys.modules} & set(%r))
print(json.dumps({"out": out.getvalue(), "status": status, "heavy": heavy}))
"""


def test_version_answers_at_once_with_the_installed_version():
    import importlib.metadata

    code = VERSION_PROBE % (HEAVY,)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    result = json.loads(done.stdout)
    assert result["out"] == f"jaxcascade {importlib.metadata.version('jaxcascade')}\n"
    assert result["status"] == 0 and result["heavy"] == []


def subparsers():
    parser = build_parser()
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return action.choices


def test_every_option_has_help_text():
    choices = subparsers()
    assert set(choices) == set(COMMANDS)
    missing = [
        f"{name} {action.dest}"
        for name, sub in choices.items()
        for action in sub._actions
        if not (action.help or "").strip() or action.help == argparse.SUPPRESS
    ]
    assert not missing


def test_effects_help_lists_every_effect_and_the_noise_model(probe):
    from jaxcascade._measured._effects import EFFECTS
    from jaxcascade._measured._noise import ARNoise

    text = " ".join(probe["texts"]["loop --help"].split())  # argparse wraps lines
    for name in [*EFFECTS, ARNoise.name]:
        assert name in text, name
