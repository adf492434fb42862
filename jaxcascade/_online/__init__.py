"""On-line identification of the cascade: the key-term regression (Vörös 2016, eqs.
16-18) in recursive least-squares form.

- `_rls`: one recursive least-squares update with forgetting (`update`), the forgetting
  schedule (`forgetting`) and the anti-windup variants (`ANTI_WINDUP`).
- `_sample`: the regressor of one sample (eqs. 17, 19-25) from a short window of past
  signals and the current estimate, built by `_regression.regression` itself.

The estimator that runs them over a record, `Recursive`, is registered with the others
(`_estimator._recursive`); the Monte-Carlo tracking study of systems that change is
`_montecarlo._tracking`.
"""

from ._rls import ANTI_WINDUP, forgetting, update
from ._sample import sample_regression, window

__all__ = ["ANTI_WINDUP", "forgetting", "sample_regression", "update", "window"]
