"""The effect library and its registry (`_base`: the interface and the cascade's
structural and output effects; `_hysteresis`: friction and hysteresis paths; `_curved`:
the curved output backlash; `_feedback`: terms inside the linear block's recursion
(`_recursion`); `_wiener`: a static map and dynamics after the cascade).

To add an effect: its class in a module here, and its entry in `EFFECTS`."""

from ._base import (
    DynamicsOrder as DynamicsOrder,
)
from ._base import (
    Effect as Effect,
)
from ._base import (
    ExtendedModel as ExtendedModel,
)
from ._base import (
    InputDelay as InputDelay,
)
from ._base import (
    OutputDrift as OutputDrift,
)
from ._base import (
    OutputFeedthrough as OutputFeedthrough,
)
from ._base import (
    OutputOffset as OutputOffset,
)
from ._base import (
    OutputSaturation as OutputSaturation,
)
from ._base import (
    PwlSegment as PwlSegment,
)
from ._base import (
    Start as Start,
)
from ._base import (
    backlash_of as backlash_of,
)
from ._base import (
    linear_orders as linear_orders,
)
from ._base import (
    padded as padded,
)
from ._base import (
    padded_to as padded_to,
)
from ._base import (
    plain as plain,
)
from ._base import (
    simulate_extended as simulate_extended,
)
from ._base import (
    simulate_padded as simulate_padded,
)
from ._base import (
    simulate_with_switches as simulate_with_switches,
)
from ._choice import (
    Choice as Choice,
)
from ._choice import (
    choose as choose,
)
from ._choice import (
    grouping as grouping,
)
from ._choice import (
    groups as groups,
)
from ._choice import (
    unchoose as unchoose,
)
from ._choice import (
    unchoose_states as unchoose_states,
)
from ._curved import (
    CurvedBacklash as CurvedBacklash,
)
from ._feedback import (
    DirectTerm as DirectTerm,
)
from ._feedback import (
    NonlinearFeedback as NonlinearFeedback,
)
from ._feedback import (
    VelocityFriction as VelocityFriction,
)
from ._hysteresis import (
    BacklashFriction as BacklashFriction,
)
from ._hysteresis import (
    BacklashFrictionContacts as BacklashFrictionContacts,
)
from ._hysteresis import (
    DahlFriction as DahlFriction,
)
from ._hysteresis import (
    InputBacklash as InputBacklash,
)
from ._hysteresis import (
    PrandtlIshlinskii as PrandtlIshlinskii,
)
from ._hysteresis import (
    SlackFriction as SlackFriction,
)
from ._wiener import (
    InnerKink as InnerKink,
)
from ._wiener import (
    InnerPolynomial as InnerPolynomial,
)
from ._wiener import (
    OutputDynamics as OutputDynamics,
)
from ._wiener import (
    OutputFold as OutputFold,
)
from ._wiener import (
    OutputPolynomial as OutputPolynomial,
)

EFFECTS: dict[str, type[Effect]] = {
    effect.name: effect
    for effect in (
        OutputOffset,
        InputDelay,
        DynamicsOrder,
        PwlSegment,
        OutputSaturation,
        OutputDrift,
        OutputFeedthrough,
        SlackFriction,
        BacklashFriction,
        BacklashFrictionContacts,
        PrandtlIshlinskii,
        DahlFriction,
        InputBacklash,
        CurvedBacklash,
        NonlinearFeedback,
        DirectTerm,
        VelocityFriction,
        OutputPolynomial,
        OutputFold,
        OutputDynamics,
        InnerPolynomial,
        InnerKink,
    )
}
# tried only when a test of their signature failed: the hysteresis paths and the curved
# backlash
HYSTERESIS = tuple(name for name, effect in EFFECTS.items() if effect.needs_signature)
# the effects that change the cascade's orders (nothing to change without a cascade)
STRUCTURAL = ("dynamics_order", "pwl_segment")
# the hysteresis paths that may also replace the cascade (a path of the input alone)
REPLACEMENTS = tuple(name for name in HYSTERESIS if EFFECTS[name].linear)
