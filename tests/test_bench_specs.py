"""The benches that derive a few functions alone (the zoo's ID, M and FD; pinocchio-cpp's ode_jac_x too)
must time the very expressions the catalogue generates: same inputs, same values at seeded states, on
a short arm and on a chain long enough to take the articulated-body algorithm, the analytic
derivatives and the ODE Jacobian as a template (the catalogue's own, calling functions the bench
derives too)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from derive.bench.large import generic_chain
from derive.bench.pinocchio_cpp import specs as bench_specs
from derive.codegen.catalogue import function_specs, template_functions
from derive.description.model import parse_models
from derive.symbolic.model import SXModel
from util import robots


@pytest.mark.parametrize("robot", [robots()["ur5"], parse_models(generic_chain(14))["chain14"]], ids=lambda r: r.name)
def test_bench_specs_are_the_catalogues(robot):
    model = SXModel(robot)
    generated = {spec.short_name: spec for spec in function_specs(model)}
    rng = np.random.default_rng(4)
    expressions, templates = bench_specs(model)
    names = {spec.short_name for spec in expressions} | {t.short_name for t in templates}
    assert "ode_jac_x" in names
    catalogue_templates = {t.short_name: t for t in template_functions(model)}
    for t in templates:  # the same template, calling functions the bench derives too
        assert t == catalogue_templates[t.short_name] and set(t.callees) <= names, t.short_name
    for spec in expressions:
        want = generated[spec.short_name]
        assert [n for n, _ in spec.inputs] == [n for n, _ in want.inputs], spec.short_name
        f = ca.Function("f", [x for _, x in spec.inputs], [e for _, e in spec.outputs])
        g = ca.Function("g", [x for _, x in want.inputs], [e for _, e in want.outputs])
        args = [rng.uniform(-1, 1, x.numel()) for _, x in spec.inputs]
        assert np.array_equal(np.array(f(*args)), np.array(g(*args))), spec.short_name
