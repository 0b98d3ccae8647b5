"""Contact-consistent inverse dynamics of a floating base (``contact_inverse_dynamics_<stance>``).

For a desired qdd the generated function returns tau (its six base entries 0) and the contact forces lambda with
M qdd + h = tau + J^T lambda, lambda the minimum-norm solution of the base rows J_b^T lambda = ID(q, qd, qdd)[0:6].
Checked at seeded states, in generated C and Python (JAX on the biped):

- the full equation of motion holds to 1e-9 (the reference's M, h and J), lambda equals numpy's lstsq of the base
  rows to 1e-9, tau's base entries are exactly 0;
- consistent with contact_dynamics: for a qdd that keeps the contacts held (J qdd + J' qd = 0, by projecting a
  random qdd onto that affine set), contact_dynamics at the returned tau gives back qdd and lambda;
- status 0 where J_b has rank < 6 (two point feet of solo12: the line through them is a free axis), 1 otherwise;
  a redundant stance (a sole and a point under it) still has a unique minimum-norm lambda and status 1.

solo12 (four feet; the trot pair for the status) from example-robot-data and the test biped of
test_contacts.py (a surface foot and a point foot), each generated once per module with only the functions needed.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from derive.description.model import parse_models, parse_robot
from derive.description.urdf import example_robot_data_dir, import_urdf_named
from derive.reference import NumericRobot
from derive.reference import contact as ref
from test_contacts import BIPED, Generated
from util import assert_close

TOL = 1e-9
QUANTITIES = ("contact_inverse_dynamics", "contact_dynamics")


def solo12_robot():
    if example_robot_data_dir() is None:
        pytest.fail("example-robot-data is not installed (the Makefile installs it with pinocchio)")
    name, entry = import_urdf_named("example-robot-data:solo_description/robots/solo12.urdf", floating=True,
                                    friction=False)
    feet = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]
    entry = {**entry, "contacts": [{"frame": f} for f in feet],
             "contact_sets": {"stance": feet, "trot": ["FL_FOOT", "HR_FOOT"]},
             "generate": {"quantities": list(QUANTITIES)}}
    return parse_robot(name, entry)


@pytest.fixture(scope="module")
def solo12(tmp_path_factory):
    return Generated(solo12_robot(), tmp_path_factory.mktemp("solo12"), jax_too=False)


@pytest.fixture(scope="module")
def biped(tmp_path_factory):
    pytest.importorskip("jax")
    import jax
    jax.config.update("jax_enable_x64", True)
    robot = dataclasses.replace(parse_models(BIPED)["biped"], generate_quantities=QUANTITIES)
    return Generated(robot, tmp_path_factory.mktemp("biped"))


def held_qdd(rng, J: np.ndarray, a0: np.ndarray) -> np.ndarray:
    """A random qdd projected onto J qdd + a0 = 0 (the minimum-norm change)."""
    a = 3 * rng.normal(size=J.shape[1])
    return a - np.linalg.lstsq(J, J @ a + a0, rcond=None)[0]


def check_stance(gen: Generated, stance: str, states: int, seed: int, jax_first: bool = False, held_too: bool = True
                 ) -> None:
    """At ``states`` seeded states, a general qdd and (``held_too``) one that holds the contacts, fed back to
    contact_dynamics."""
    robot = gen.robot
    nr = NumericRobot(robot)
    frames = next(s.frames for s in robot.stances if s.name == stance)
    kinds = [(f, robot.contact(f).kind) for f in frames]
    rng = np.random.default_rng(seed)
    for k in range(states):
        q = nr.random_configuration(rng)
        v = rng.normal(size=nr.nv)
        J, a0 = ref.contact_rows(nr, q, v, kinds)
        # a general qdd (the contacts accelerate) and one that keeps them held
        for held, qdd in ((False, 3 * rng.normal(size=nr.nv)), (True, held_qdd(rng, J, a0)))[:1 + held_too]:
            M, h = nr.crba(q), nr.rnea(q, v, np.zeros(nr.nv))
            lam_ls = np.linalg.lstsq(J[:, :6].T, (M @ qdd + h)[:6], rcond=None)[0]
            results = gen.all(f"contact_inverse_dynamics_{stance}", q, v, qdd, jax=jax_first and k == 0)
            for lang, (tau, lam, status) in zip(("Python", "C", "JAX"), results):
                tau, lam = tau.ravel(), lam.ravel()
                assert status.item() == 1.0, lang
                assert np.all(tau[:6] == 0.0), f"{lang}: the base is unactuated"
                assert_close(tau + J.T @ lam, M @ qdd + h, TOL, f"{lang}: M qdd + h = tau + J^T lambda")
                assert_close(lam, lam_ls, TOL, f"{lang}: lambda = lstsq's minimum-norm solution")
            tau, lam, _ = results[0]
            if held:  # J qdd + a0 = 0: contact_dynamics gives qdd back
                assert_close(J @ qdd, -a0, TOL, "the projected qdd holds the contacts")
                for lang, (qdd_c, lam_c, status) in zip(("Python", "C"), gen.all(f"contact_dynamics_{stance}", q, v,
                                                                                  tau.ravel(), jax=False)):
                    assert status.item() == 1.0
                    assert_close(qdd_c.ravel(), qdd, TOL, f"{lang}: contact_dynamics(tau) = qdd")
                    assert_close(lam_c.ravel(), lam.ravel(), TOL, f"{lang}: contact_dynamics(tau)'s lambda (unique)")


def test_solo12_four_feet(solo12):
    """solo12 standing on its four feet (12 rows): the equation of motion, lstsq's lambda, contact_dynamics
    gives qdd back, in C and Python."""
    assert [o["shape"] for o in solo12.fn["contact_inverse_dynamics_stance"]["outputs"]] == [[18, 1], [12, 1], [1, 1]]
    check_stance(solo12, "stance", 3, 0)


def test_solo12_two_feet_cannot_hold_the_base(solo12):
    """Two point feet (6 rows) have J_b of rank 5 (the base turns freely about the line through them): status 0
    in C and Python, finite numbers."""
    nr = NumericRobot(solo12.robot)
    rng = np.random.default_rng(1)
    for _ in range(2):
        q, v, a = nr.random_configuration(rng), rng.normal(size=nr.nv), rng.normal(size=nr.nv)
        for lang, outs in zip(("Python", "C"), solo12.all("contact_inverse_dynamics_trot", q, v, a, jax=False)):
            assert outs[-1].item() == 0.0 and all(np.isfinite(x).all() for x in outs), lang


def test_biped_surface_and_point(biped):
    """The biped's sole and point foot (9 rows) in C, Python and JAX; its redundant stance (a sole and a point
    under it: rows of rank 6) still has J_b of rank 6, a unique minimum-norm lambda and status 1 (no qdd holds
    both: the sole's drift is its spatial acceleration, the point's its classical one)."""
    check_stance(biped, "both", 2, 2, jax_first=True)
    check_stance(biped, "redundant", 2, 3, held_too=False)  # the drifts disagree (spatial vs classical): none held


def test_only_floating_stances_of_six_rows():
    """A fixed base, or a stance of fewer than 6 rows, gets no contact_inverse_dynamics (the base rows would not
    hold for a general qdd)."""
    from derive.codegen.catalogue import function_specs
    from derive.symbolic.model import SXModel
    text = BIPED.replace("      redundant: [l_foot, l_point]", "      redundant: [l_foot, l_point]\n      one: [r_foot]")
    robot = dataclasses.replace(parse_models(text)["biped"], generate_quantities=("contact_inverse_dynamics",))
    names = [s.name for s in function_specs(SXModel(robot)) if s.quantity == "contact_inverse_dynamics"]
    assert names == ["biped_contact_inverse_dynamics_both", "biped_contact_inverse_dynamics_redundant"]
