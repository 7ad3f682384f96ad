"""Regularisers of the decision vector: the ‖u‖²_R term of Fahmi et al. 2019, eq. 7a, and the two
force-regularisation schemes of their Sect. V-D, as equality tasks toward zero."""

from __future__ import annotations

import math

import numpy as np

from ..robot import FREE_FLYER_NV
from .base import (Task, TaskRows, checked_attribute, contact_list, contact_subset, scalar_rule,
                   vector_rule)
from . import schema
from .contact import _PerContact, tangent_rows


class AccelerationRegularizer(Task):
    """q̈ ≈ 0 (all nv rows, base included)."""

    kernel = "acceleration_regularizer"

    def row_count(self, layout):
        return layout.robot.nv

    def rows(self, robot, variables):
        return TaskRows(qdd=np.eye(robot.nv), lam=None, tau=None, target=np.zeros(robot.nv))


class AccelerationTarget(AccelerationRegularizer):
    """q̈ ≈ ``target`` (nv,): the regulariser pulled toward given accelerations (PassiveWBC's
    posture regulariser: 0 on the base, a PD toward the posture on the joints)."""

    target = checked_attribute(vector_rule(), "Accelerations (nv,), finite.")
    kernel = "acceleration_target"
    params = (schema.vector("target", 1, "nv"),)

    def __init__(self, target, name=None, weight=1.0):
        super().__init__(name, weight)
        self.target = target

    def rows(self, robot, variables):
        return TaskRows(qdd=np.eye(robot.nv), lam=None, tau=None, target=self.target.copy())


class AuxiliaryRegularizer(Task):
    """Named auxiliary variables ≈ 0 (one row per entry): the cost α‖ε‖² (``weight`` √α) on
    slacks another task declares, e.g. :class:`~wholebody.tasks.motion.SlackedFrameTask`'s."""

    kernel = "auxiliary_regularizer"

    def __init__(self, names, name=None, weight=1.0):
        if isinstance(names, str) or not names or not all(isinstance(n, str) for n in names):
            raise ValueError(f"names: expected a non-empty list of auxiliary variable names, "
                             f"got {names!r}")
        super().__init__(name or f"auxiliary {','.join(names)}", weight)
        self.names = tuple(names)

    def auxiliary(self):
        return dict.fromkeys(self.names)  # sizes declared by the tasks that own them

    def layout_key(self):
        return self.names

    def row_count(self, layout):
        return layout.count("auxiliary")

    def rows(self, robot, variables):
        columns = variables.auxiliary_columns(self.names, f"task '{self.name}'")
        aux = np.zeros((len(columns), variables.n_aux))
        aux[np.arange(len(columns)), columns] = 1.0
        return TaskRows(qdd=None, lam=None, tau=None, aux=aux, target=np.zeros(len(columns)))


class TangentialForceRegularizer(_PerContact):
    """Tangential components of point-contact forces ≈ 0: forces near the cone normals (Sect. V-D,
    "robustness to uncertainties in the friction parameters"). 2 rows per contact. ``contacts``:
    None = all active contacts, an empty list = none (no rows); ``normals`` finite, non-zero.

    ``lean`` (a force, e.g. the desired net contact force; ours): each force's tangential part
    measured from the lean's direction instead (:func:`~wholebody.tasks.contact.tangent_rows`,
    its ratio capped at ``mu``), so that every contact uses the same friction ratio and none is
    pushed to its cone's edge while others stay near the normal."""

    lean = checked_attribute(vector_rule(3, optional=True), "None or a finite force (3,).")
    mu = checked_attribute(scalar_rule(low=0.0, low_open=True, allow_inf=True),
                           "Largest friction ratio of the lean, > 0 (inf: no cap).")
    kernel = "tangential_force_regularizer"
    # a lean of zero presses into no surface: the same rows as None
    params = (schema.scalar("mu"),
              schema.vector("lean", 3,
                            get=lambda t, layout, state: 0.0 if t.lean is None else t.lean),
              _PerContact.NORMALS)

    def __init__(self, name=None, weight=1.0, contacts=None, normals=None, lean=None,
                 mu: float = math.inf):
        super().__init__(name, weight, contacts, normals)
        self.lean = lean
        self.mu = mu

    def row_count(self, layout):
        return 2 * layout.count("contact")

    def rows(self, robot, variables):
        names = contact_subset(variables, self.contacts)
        A = np.zeros((2 * len(names), variables.n_lambda))
        for i, n in enumerate(names):
            sl = variables.lambda_slices[n]
            A[2 * i:2 * i + 2, sl.start:sl.start + 3] = tangent_rows(self.normal(n), self.lean,
                                                                      self.mu)
        return TaskRows(qdd=None, lam=A, tau=None, target=np.zeros(A.shape[0]))


class ContactTorqueRegularizer(Task):
    """Joint torques of the contact forces ≈ 0, per-joint weights (Sect. V-D, footnote 16:
    R_F = J_st,j R_τ J_st,jᵀ): rows −J_st,jᵀ λ; ``weight`` is √R_τ per joint. ``contacts``:
    None = all active contacts, an empty list = none (the rows are then zero)."""

    contacts = checked_attribute(contact_list, "None (all active contacts) or contact names.")
    per_contact = True
    kernel = "contact_torque_regularizer"

    def __init__(self, name=None, weight=1.0, contacts=None):
        super().__init__(name, weight)
        self.contacts = contacts

    def row_count(self, layout):
        return layout.robot.na

    def rows(self, robot, variables):
        names = contact_subset(variables, self.contacts)
        A = np.zeros((robot.na, variables.n_lambda))
        for n in names:
            sl = variables.lambda_slices[n]
            A[:, sl] = -robot.contact_jacobians[n][:, FREE_FLYER_NV:].T
        return TaskRows(qdd=None, lam=A, tau=None, target=np.zeros(robot.na))
