"""Risk labelling: the sampling-tree estimator (Alg. 1), coherent risk metrics, datasets (Alg. 2).

The estimator labels a :class:`RiskScene` (dynamics in one obstacle configuration, see
:mod:`rmm_envs.scenes`); datasets and the ``RiskLabel`` wrapper reach it through an env that
follows the :class:`LabelledEnv` protocol (:func:`check_labelled_env`).
"""

from rmm_envs.risk.estimator import RiskEstimator, RiskResult
from rmm_envs.risk.metrics import METRICS, cvar, expected, get_metric, worst_case
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
