"""Forward dynamics by the articulated-body algorithm (derive.symbolic.aba) against CRBA and LDL^T, at
seeded random states: a branched tree with revolute, prismatic, spherical and helical joints,
actuators (armature, friction) and parameters, and a chain long enough that the generated forward
dynamics take the ABA, which the Panda's do not (CRBA and LDL^T are cheaper there)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from derive.bench.large import generic_chain
from derive.codegen.catalogue import function_specs
from derive.description.model import parse_models
from derive.symbolic import aba
from derive.symbolic.model import ABA_COMPARE_MAX_NV, SXModel
from derive.symbolic.ode import forward_dynamics
from test_derivatives import TREE
from util import robots


@pytest.mark.parametrize("robot", [parse_models(TREE)["tree"], parse_models(generic_chain(ABA_COMPARE_MAX_NV + 2))[
    f"chain{ABA_COMPARE_MAX_NV + 2}"]], ids=lambda r: r.name)
def test_aba_equals_crba_and_ldlt(robot):
    model = SXModel(robot)
    s, ne = model.sym, model.newton_euler
    by_ldl = forward_dynamics(ne.mass_matrix, ne.bias, s.tau, ne.dof_parents)
    inputs = [s.q, s.qd, s.tau] + ([s.p] if s.p.numel() else [])
    f = ca.Function("f", inputs, [aba.forward_dynamics(ne, s.tau), by_ldl, model.forward_dynamics()])
    p = [np.array([x.default for x in robot.parameters])] if s.p.numel() else []
    rng = np.random.default_rng(5)
    for _ in range(4):
        got, want, generated = (np.array(v) for v in f(rng.uniform(-2, 2, s.nv), rng.normal(size=s.nv),
                                                       rng.normal(size=s.nv), *p))
        assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max()
        assert np.array_equal(generated, got if model.articulated else want)
    assert model.articulated == (s.nv > ABA_COMPARE_MAX_NV)  # the tree (9) keeps CRBA, the long chain takes the ABA
    fd = next(spec for spec in function_specs(model) if spec.short_name == "forward_dynamics")
    assert dict(fd.manifest)["algorithm"] == ("articulated-body algorithm" if model.articulated else "CRBA, then LTDL along the tree")


def test_short_arms_keep_crba_and_ldlt():
    assert not SXModel(robots()["panda"]).articulated
