"""SVCPartitionedGP: classifier options that the fitted model does not use are named."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from synthetic import tiny_stand

from clutchlab.errors import ParameterWarning
from clutchlab.residual_ml import SVCPartitionedGP

SMALL = {"n_hyper": 200, "max_points": 300}


@pytest.fixture(scope="module")
def train():
    return tiny_stand(3).select(ramps=["fast", "slow"])


def test_classifier_options_a_latch_law_ignores_are_named(train):
    """With the default latch_model="local_event" the law decides: classifier and svc_*
    were accepted and ignored (the same prediction to the last bit), without a word."""
    plain = SVCPartitionedGP(**SMALL).fit(train)
    assert plain.latch_model_ == "local_event"
    with pytest.warns(ParameterWarning) as record:
        other = SVCPartitionedGP(classifier="logistic_regression", svc_C=1.0, **SMALL).fit(train)
    text = str(record[0].message)
    assert "classifier='logistic_regression', svc_C=1.0 had no effect" in text
    assert "local_event law" in text and "latch_model='classifier'" in text
    assert record[0].filename == __file__
    tr = train[0]
    np.testing.assert_array_equal(other.predict(tr), plain.predict(tr))  # what was ignored


def test_no_warning_when_the_options_act_or_are_left_alone(train):
    with warnings.catch_warnings():
        warnings.simplefilter("error", ParameterWarning)
        SVCPartitionedGP(**SMALL).fit(train)
        used = SVCPartitionedGP(
            latch_model="classifier", classifier="logistic_regression", svc_C=1.0, **SMALL
        ).fit(train)
    assert used.latch_model_ == "classifier" and used.classifier_ is not None
