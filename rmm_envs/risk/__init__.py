"""Risk labelling: the sampling-tree estimator (Alg. 1), coherent risk metrics, datasets (Alg. 2).

The estimator labels a :class:`RiskScene` (dynamics in one obstacle configuration, see
:mod:`rmm_envs.scenes`); datasets and the ``RiskLabel`` wrapper reach it through an env that
follows the :class:`LabelledEnv` protocol (:func:`check_labelled_env`).
"""

from rmm_envs.risk.estimator import RiskEstimator, RiskResult
from rmm_envs.risk.metrics import METRICS, cvar, expected, get_metric, worst_case
from rmm_envs._deprecated import renamed_attributes
from rmm_envs.risk.protocol import LabelledEnv, RiskScene, check_labelled_env, check_scene

__all__ = [
    "METRICS",
    "LabelledEnv",
    "RiskEstimator",
    "RiskResult",
    "RiskScene",
    "check_labelled_env",
    "check_scene",
    "cvar",
    "expected",
    "get_metric",
    "worst_case",
]

#: ``System`` and ``check_system``, the former names of :class:`RiskScene` and :func:`check_scene`,
#: answered with a ``DeprecationWarning``.
__getattr__ = renamed_attributes(__name__, {"System": ("rmm_envs.risk.protocol:RiskScene", "rmm_envs.risk.RiskScene"),
                                            "check_system": ("rmm_envs.risk.protocol:check_scene",
                                                             "rmm_envs.risk.check_scene")})
