"""The estimators' parameters in scikit-learn's layout: declared once (default and constraint
together), stored as given, checked when learning starts, read and changed by get_params and
set_params, so that sklearn.base.clone works; scikit-learn itself stays out of the product."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from gngdt.core import GNG, GNGDT, GNGW

POINTS = np.random.default_rng(0).random((500, 3))
COLORS = np.random.default_rng(1).random((500, 3)) * 255


@pytest.mark.parametrize("cls", [GNGDT, GNG, GNGW])
def test_every_parameter_has_one_default_and_one_constraint(cls) -> None:
    import inspect

    signature = inspect.signature(cls)
    assert set(cls._parameter_constraints) == set(signature.parameters)
    assert all(p.default is not p.empty and p.kind == p.KEYWORD_ONLY
               for p in signature.parameters.values())
    defaults = cls()
    assert defaults.check_params()["max_nodes"] == cls.max_nodes == 1000


def test_clone_gives_an_unfitted_estimator_with_the_same_parameters() -> None:
    clone = pytest.importorskip("sklearn.base").clone
    given = {"max_nodes": 50, "lambda_": 100, "utility_k": 10.0, "viewpoint": (0.0, 0.0, 1.0),
             "random_state": 3}
    model = GNGDT(**given).fit(POINTS, COLORS, n_steps=3_000)
    assert model.n_nodes_ > 2
    copy = clone(model)
    assert type(copy) is GNGDT and copy is not model
    assert copy.get_params() == model.get_params()
    assert {name: copy.get_params()[name] for name in given} == given
    assert copy.n_nodes_ == 0 and copy.n_steps_ == 0
    # the same parameters and seed learn the same network
    copy.fit(POINTS, COLORS, n_steps=3_000)
    np.testing.assert_array_equal(copy.positions_, model.positions_)
    for cls in (GNG, GNGW):
        assert clone(cls(max_nodes=40, random_state=1)).get_params() == cls(
            max_nodes=40, random_state=1).get_params()


def test_parameters_are_stored_as_given_and_checked_when_learning_starts() -> None:
    viewpoint = [0.0, 0.0, 1.0]
    model = GNGDT(max_nodes=50, viewpoint=viewpoint, utility_k=0)
    assert model.viewpoint is viewpoint and model.get_params()["viewpoint"] is viewpoint
    assert model.utility_k == 0  # stored as given; 0 turns forgetting off when checked
    checked = model.check_params()
    assert checked["utility_k"] is None and checked["viewpoint"] == (0.0, 0.0, 1.0)
    bad = GNGDT(max_nodes=1)  # no error until it learns
    with pytest.raises(ValueError, match="max_nodes"):
        bad.partial_fit(POINTS, n_steps=10)


def test_set_params_then_partial_fit_validates() -> None:
    model = GNGDT(max_nodes=50, lambda_=100, random_state=0).fit(POINTS, COLORS, n_steps=2_000)
    assert model.set_params(eta1=2.0) is model
    with pytest.raises(ValueError, match="eta1"):
        model.partial_fit(POINTS, COLORS, n_steps=100)
    model.set_params(eta1=0.01, eta2=0.05)
    with pytest.raises(ValueError, match="eta2"):
        model.partial_fit(POINTS, COLORS, n_steps=100)
    steps = model.n_steps_
    model.set_params(eta1=0.05, eta2=0.001)  # how it learns may change between batches
    model.partial_fit(POINTS, COLORS, n_steps=100)
    assert model.n_steps_ == steps + 100
    # what its state holds may not: a new budget takes a new network
    model.set_params(max_nodes=80)
    with pytest.raises(ValueError, match="max_nodes"):
        model.partial_fit(POINTS, COLORS, n_steps=100)
    model.fit(POINTS, COLORS, n_steps=8_000)
    assert model.growth_limit_ == 80 and 50 < model.n_nodes_ <= 80


def test_an_unknown_parameter_is_refused() -> None:
    with pytest.raises(TypeError, match="colour_threshold"):
        GNGDT(colour_threshold=3.0)
    model = GNGDT(max_nodes=50)
    with pytest.raises(ValueError, match="colour_threshold"):
        model.set_params(max_nodes=60, colour_threshold=3.0)
    assert model.max_nodes == 50  # nothing changed
    with pytest.raises(ValueError, match="w_pos"):
        GNGDT().set_params(w_pos=0.5)  # GNG-W's, not GNG-DT's


def test_a_checkpoint_keeps_the_checked_parameters() -> None:
    model = GNGDT(max_nodes=50, utility_k=0, random_state=2).fit(POINTS, COLORS, n_steps=2_000)
    restored = GNGDT.from_state(model.get_state())
    assert restored.max_nodes == 50 and restored.utility_k is None
    restored.partial_fit(POINTS, COLORS, n_steps=500)
    model.partial_fit(POINTS, COLORS, n_steps=500)
    np.testing.assert_array_equal(restored.positions_, model.positions_)


def test_learning_never_imports_scikit_learn() -> None:
    code = ("import sys, numpy as np\nfrom gngdt.core import GNGDT\n"
            "GNGDT(max_nodes=20, random_state=0).fit(np.random.rand(200, 3), n_steps=500)\n"
            "print('sklearn' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=300)
    assert out.stdout.strip() == "False"
