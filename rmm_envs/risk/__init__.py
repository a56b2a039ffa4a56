"""Risk labelling: the sampling-tree estimator (Alg. 1), coherent risk metrics, datasets (Alg. 2)."""

from rmm_envs.risk.estimator import RiskEstimator, RiskResult
from rmm_envs.risk.metrics import METRICS, cvar, expected, get_metric, worst_case
from rmm_envs.risk.protocol import System, check_system

__all__ = [
    "METRICS",
    "RiskEstimator",
    "RiskResult",
    "System",
    "check_system",
    "cvar",
    "expected",
    "get_metric",
    "worst_case",
]
