"""`_names` (the registries' names, for `--help` without JAX) equals each registry, and the
docs' list of the loop's effects (docs/loop.md) is the library's."""

import pathlib
import re

from jaxcascade import _names
from jaxcascade._benchmark._robust import SYSTEMS
from jaxcascade._estimator import BUILTIN, ESTIMATORS
from jaxcascade._experiment._disturbance import NOISES
from jaxcascade._experiment._inputs import INPUTS
from jaxcascade._measured._effects import EFFECTS
from jaxcascade._measured._noise import ARNoise
from jaxcascade._montecarlo._spec import FAMILIES

LOOP_PAGE = pathlib.Path(__file__).parents[1] / "docs" / "loop.md"


def test_names_equal_the_registries():
    # the package's own (a user's registered estimators join `ESTIMATORS` at run time)
    assert _names.ESTIMATORS == {name: ESTIMATORS[name].summary for name in BUILTIN}
    assert _names.EFFECTS == {name: effect.description for name, effect in EFFECTS.items()}
    assert _names.NOISE_MODEL == ARNoise.name
    assert _names.NOISE_MODEL_DESCRIPTION == ARNoise.description
    assert _names.FAMILIES == tuple(FAMILIES)
    assert _names.BENCH_SYSTEMS == tuple(SYSTEMS)
    assert _names.INPUTS == {name: cls.summary for name, cls in INPUTS.items()}
    assert _names.NOISES == {name: cls.summary for name, cls in NOISES.items()}


def test_docs_list_the_loops_effects():
    text = " ".join(LOOP_PAGE.read_text().split())
    listed = text.split("Otherwise each effect of the library (", 1)[1].split(")", 1)[0]
    assert re.findall(r"`([a-z_]+)`", listed) == [*EFFECTS, ARNoise.name]
