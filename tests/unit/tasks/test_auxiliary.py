"""Auxiliary decision variables owned by tasks (a slack): their columns in Variables, the stack's
collection of them, SlackedFrameTask's ∞-norm bound checked from the robot's own frame terms,
and the reduced and full formulations (aux columns after λ, resp. τ) giving the same torques."""

import numpy as np
import pytest

from wholebody.formulation import Formulation, Stack
from wholebody.solvers import SolverSettings
from wholebody.tasks import (AuxiliaryRegularizer, ContactConstraint, FrictionCone,
                             FullDynamics, NewtonEuler, PostureTask, SlackedFrameTask,
                             TorqueLimits)
from wholebody.variables import Variables

# ε negligible: the full formulation regularises τ too, the reduced one does not
SETTINGS = SolverSettings(method="weighted", backend="daqp", fallback_backend=None,
                          regularization=1e-12)


@pytest.mark.parametrize("auxiliary,match", [
    ({"e": 0}, r"auxiliary\['e'\]: expected a size >= 1, got 0"),
    ({"e": 1.5}, r"auxiliary\['e'\]: expected a size >= 1, got 1.5"),
    ({"e": True}, r"auxiliary\['e'\]: expected a size >= 1, got True"),
    ({3: 1}, "auxiliary: names must be strings, got 3")])
def test_bad_auxiliary_variables_name_the_field(robots, auxiliary, match):
    with pytest.raises(ValueError, match=match):
        Variables(robots["talos14"], auxiliary=auxiliary)


def test_columns_follow_the_declared_order(robots):
    robot = robots["talos14"]
    variables = Variables(robot, ["left_sole"], {"b": 2, "a": 1})
    assert variables.n_aux == 3 and variables.n_full == robot.nv + 6 + robot.na + 3
    assert variables.auxiliary_columns(["a", "b"], "task 't'") == [2, 0, 1]
    with pytest.raises(ValueError, match=r"task 't': no auxiliary variable named 'c'"):
        variables.auxiliary_columns(["c"], "task 't'")


def test_stack_collects_sizes_and_refuses_conflicts(robots):
    frame = "left_sole_link"
    owner = SlackedFrameTask(frame, "e", name="owner")
    assert Stack([[owner], [AuxiliaryRegularizer(["e"])]]).auxiliary() == {"e": 1}
    with pytest.raises(ValueError, match=r"no task declares the size of \['f'\]"):
        Stack([[owner], [AuxiliaryRegularizer(["f"])]]).auxiliary()

    class Wide(SlackedFrameTask):
        def auxiliary(self):
            return {self.slack: 2}
    with pytest.raises(ValueError, match="task 'wide': auxiliary variable 'e' has size 2"):
        Stack([[owner, Wide(frame, "e", name="wide")]]).auxiliary()


@pytest.mark.parametrize("kwargs,match", [
    ({"frame": "left_sole_link", "slack": ""}, "slack: expected the auxiliary variable's name"),
    ({"frame": "left_sole_link", "slack": None}, "slack: expected the auxiliary variable's name")])
def test_bad_slack_name(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SlackedFrameTask(**kwargs)


def test_bad_regularized_names():
    with pytest.raises(ValueError, match="names: expected a non-empty list"):
        AuxiliaryRegularizer("slack")


def stack_with_a_slacked_foot(robot, full=False, cost=1.0):
    """Double support on the right sole; the left foot asked to move 0.3 m in one step (its PD
    needs more than the torque limits give): its rows within one slack, costed."""
    foot = SlackedFrameTask("left_sole_link", "slack", kp=400.0, kd=40.0, mask="position",
                            name="left foot")
    foot.position = robot.frame_placement("left_sole_link")[0] + np.array([0.3, 0.1, 0.2])
    return Stack([[FullDynamics() if full else NewtonEuler(), TorqueLimits(),
                   ContactConstraint(), FrictionCone(0.8), foot],
                  [AuxiliaryRegularizer(["slack"], weight=cost),
                   PostureTask(kp=10.0, kd=2.0, weight=1e-2)]])


def test_slack_is_the_infinity_norm_of_the_frame_residual(robots):
    """|J q̈ + J̇ v − a_d| ≤ ε row by row and ε equals the largest (the cost pushes ε down to
    it); the residual from the robot's frame Jacobian and drift, a_d the PD of the foot's pose."""
    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    stack = stack_with_a_slacked_foot(robot)
    variables = Variables(robot, ["right_sole"], stack.auxiliary())
    sol = Formulation(robot).solve(stack, variables, SETTINGS)
    assert sol.ok, sol.status
    eps = float(sol.auxiliary["slack"][0])
    frame = "left_sole_link"
    position = robot.frame_placement(frame)[0]
    J = robot.frame_jacobian(frame)[:3]
    desired = 400.0 * (stack.find("left foot").position - position)  # at rest: no D term
    residual = J @ sol.qdd + robot.frame_drift(frame)[:3] - desired
    assert eps > 1.0  # the slack takes up what the foot cannot do
    assert np.all(np.abs(residual) <= eps + 1e-6)
    assert np.abs(residual).max() == pytest.approx(eps, rel=1e-6)
    report = {t.name: t for t in Formulation.task_reports(
        np.r_[sol.qdd, sol.lam / (robot.mass * 9.81), sol.auxiliary["slack"]],
        Formulation(robot).levels(stack, variables)[1])}
    assert report["left foot"].error < 1e-6  # the relaxed rows hold


def test_reduced_and_full_formulations_agree(robots):
    """The auxiliary columns come after λ (reduced) or after τ (full): the same torques and
    slack from both."""
    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    solutions = []
    for full in (False, True):
        stack = stack_with_a_slacked_foot(robot, full=full, cost=3.0)
        variables = Variables(robot, ["right_sole"], stack.auxiliary())
        solutions.append(Formulation(robot, reduced=not full).solve(stack, variables, SETTINGS))
    reduced, full = solutions
    assert reduced.ok and full.ok
    np.testing.assert_allclose(full.tau, reduced.tau, atol=1e-5)
    np.testing.assert_allclose(full.auxiliary["slack"], reduced.auxiliary["slack"], rtol=1e-6)


@pytest.mark.parametrize("engine", ["python", "native"])
def test_a_slacked_task_in_a_controllers_stack(robots, engine):
    """A task with a slack inserted into a controller's stack (MomentumBalance's Table 2, whose
    variables name no auxiliary variable): each engine adds the slack to the variables the
    controller passes, the torques equal the Formulation's on the same stack with the slack
    declared, and the slack's value is reported."""
    from conftest import native_cycle_or_skip

    from wholebody.control import MomentumBalance
    if engine == "native":
        native_cycle_or_skip("_hierarchy_cycle")
    robot = robots["talos14"]
    ctrl = MomentumBalance(robot, gains="pd", engine=engine)
    lean = SlackedFrameTask("torso_2_link", "lean", kp=50.0, kd=10.0, mask="orientation",
                            name="torso within a slack")
    lean.rotation = np.eye(3)
    ctrl.stack.insert(1, lean)
    ctrl.stack.insert(2, AuxiliaryRegularizer(["lean"], weight=10.0))
    assert ctrl.variables.auxiliary == ()
    q, v = robot.q_ref.copy(), np.zeros(robot.nv)
    q[7:] += 0.05
    sol = ctrl.compute(q, v, 0.0)
    assert sol.ok, sol.status
    assert set(sol.auxiliary) == {"lean"} and sol.auxiliary["lean"][0] > 0.0
    robot.update(q, v)
    variables = Variables(robot, ctrl.variables.contacts, {"lean": 1})
    ref = Formulation(robot).solve(ctrl.stack, variables, ctrl.settings)
    np.testing.assert_allclose(sol.tau, ref.tau, atol=1e-6)
    np.testing.assert_allclose(sol.auxiliary["lean"], ref.auxiliary["lean"], atol=1e-8)
