"""High-order control barrier function (HOCBF) guardians: ``cbf`` and ``cbf-paper``.

Both read **privileged** data (true state, obstacles, goal, sim time) and solve one QP per
decision, after Xiao & Belta's HOCBFs as in the paper.  ``cbf`` is a safety filter: it keeps the
driver's ``info["nominal_control"]`` as close as the barriers allow, decides for the state one
lap ahead, recovers instead of braking forever and keeps its margin off the goal.
``cbf-paper`` is the paper's CBF-CLF QP at the observed state, braking when infeasible.  The
name ``cbf`` also serves the maze car and the quadrotor (dispatched on the action space's dynamics).

Offers :class:`CBFGuardian` and :class:`CBFPaperGuardian`; their settings and presets are in
:mod:`rmm_guardians.cbf.settings`, the rows in :mod:`~rmm_guardians.cbf.barrier`, the QP in
:mod:`~rmm_guardians.cbf.qp` and :mod:`~rmm_guardians.cbf.backend`, the backup manoeuvre in
:mod:`~rmm_guardians.cbf.recovery`, the other systems in :mod:`~rmm_guardians.cbf.maze` and
:mod:`~rmm_guardians.cbf.quadrotor`.  Why: docs/decisions/0014-cbf-safety-filter.md (0015, 0016).
"""

from rmm_guardians.cbf.guardian import CBFGuardian, CBFPaperGuardian

__all__ = ["CBFGuardian", "CBFPaperGuardian"]
