"""jaxcascade: identification of three-block cascade systems with backlash (Vörös 2016)."""

from ._estimate import Solution as Solution
from ._estimate import initial_guess as initial_guess
from ._estimate import voros as voros
from ._examples import EXAMPLES as EXAMPLES
from ._examples import Example as Example
from ._examples import example as example
from ._model import (
    CascadeParams as CascadeParams,
)
from ._model import (
    Orders as Orders,
)
from ._model import (
    is_admissible as is_admissible,
)
from ._model import (
    is_stable as is_stable,
)
from ._regression import regression as regression
from ._simulate import (
    add_noise as add_noise,
)
from ._simulate import (
    backlash as backlash,
)
from ._simulate import (
    linear_block as linear_block,
)
from ._simulate import (
    measure as measure,
)
from ._simulate import (
    pwl as pwl,
)
from ._simulate import (
    signals as signals,
)
from ._simulate import (
    simulate as simulate,
)
from ._simulate import (
    uniform_input as uniform_input,
)
from ._status import Status as Status
from ._status import status_names as status_names

__version__ = "0.1.0"
