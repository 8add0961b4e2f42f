"""DenseCall: a compiled chunk called through CasADi's buffer gives what a plain call gives."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from clutchlab.physics.dense_call import DenseCall


def _mapped() -> ca.Function:
    x, u, p = ca.SX.sym("x", 2), ca.SX.sym("u", 3), ca.SX.sym("p", 2, 2)
    step = ca.Function(
        "step",
        [x, u, p],
        [ca.mtimes(p, x) + u[:2], ca.sumsqr(x) * u[2]],
        ["x0", "u", "p"],
        ["x1", "y"],
    )
    return step.mapaccum("chunk", 7, ["x0"], ["x1"])


def test_equals_the_plain_call_with_a_broadcast_input():
    fn = _mapped()
    rng = np.random.default_rng(0)
    x0, u, p = rng.normal(size=2), rng.normal(size=(3, 7)), 0.5 * rng.normal(size=(2, 2))
    want = [np.asarray(v) for v in fn(x0, u, p)]  # CasADi repeats p over the 7 samples
    call = DenseCall(fn)
    call.fix(p=p)
    got = call(x0=x0, u=u)
    for g, w in zip(got, want, strict=True):
        assert g.shape == w.shape
        np.testing.assert_array_equal(g, w)
    # a result passed back as an argument (the next chunk's start) is copied in first
    again = call(x0=got[0][:, -1], u=u)
    want2 = [np.asarray(v) for v in fn(want[0][:, -1], u, p)]
    np.testing.assert_array_equal(again[0], want2[0])


def test_wrong_sizes_and_missing_inputs_are_named():
    call = DenseCall(_mapped())
    with pytest.raises(ValueError, match="input u is 3×7"):
        call(x0=np.zeros(2), u=np.zeros((3, 2)), p=np.eye(2))
    with pytest.raises(ValueError, match=r"no value for \['p'\]"):
        call(x0=np.zeros(2), u=np.zeros((3, 7)))
    with pytest.raises(ValueError, match="has no input 'q'"):
        call(q=1.0)


def test_a_failing_evaluation_is_not_swallowed_and_sparse_functions_are_refused():
    x = ca.MX.sym("x")
    checked = ca.Function("checked", [x], [(2 * x).attachAssert(x > 0, "x must be positive")])
    call = DenseCall(checked)
    np.testing.assert_array_equal(call(i0=1.5)[0], [[3.0]])
    with pytest.raises(RuntimeError, match="x must be positive"):
        call(i0=-1.0)
    sparse = ca.Function("sp", [x], [ca.MX(ca.Sparsity.lower(2), ca.vertcat(x, x, x))])
    with pytest.raises(ValueError, match="output o0 is not dense"):
        DenseCall(sparse)
