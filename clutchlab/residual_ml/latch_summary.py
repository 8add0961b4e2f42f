"""One line that says what decides a fitted model's latch state, and why.

Used by ``clutchlab train`` (its output and ``--json``) and by the validation report (the
variant's description), so a calibration engineer sees the same words in both: which law
or classifier, its bandwidth, whether the switch currents were found to follow line
pressure (and the held-out evidence), how many training experiments never latched, and the
training latch-state accuracy.
"""

from __future__ import annotations

import math
import re

from .latch_event import event_features

__all__ = ["LATCH_NAMES", "latch_decision_text"]

#: How each latch decision is named.
LATCH_NAMES = {
    "local_event": "local latch-event law (a line in dI/dt per dither setting)",
    "event": "latch-event law (one plane over the dither settings)",
    "classifier": "classifier",
    "none": "none (one latch state in the training data)",
}


def latch_decision_text(model) -> str | None:
    """What decides the latch state of ``model`` (or of a hybrid's residual model).

    Parameters
    ----------
    model : object
        A fitted estimator; those without a latch decision (``latch_model_``) give None.

    Returns
    -------
    str or None
        E.g. "local latch-event law (...), bandwidth 0.2, switch currents follow line
        pressure by +39.9 mA/bar (held-out error x0.44, permutation p 0.005); training
        latch-state accuracy 99.97 %".
    """
    est = getattr(model, "residual_", None) or model
    kind = getattr(est, "latch_model_", None)
    if kind is None:
        return None
    text = LATCH_NAMES.get(kind, kind)
    if kind == "local_event":
        dec = est.decision_
        text += f", bandwidth {dec.bandwidth:g}"
        evidence = f"held-out error x{dec.line_ratio:.2f}, permutation p {dec.line_p_value:.3f}"
        if dec.uses_line:
            coupling = f"{dec.line_coef:+.1f} mA/bar"
            text += f", switch currents follow line pressure by {coupling} ({evidence})"
        elif math.isfinite(dec.line_ratio):
            text += f", no line-pressure coupling ({evidence})"
        if len(dec.censored):
            text += (
                f", {len(dec.censored)} training experiment(s) never latched up to their peak "
                "current (their settings are held unlatched below it)"
            )
    elif kind == "classifier" and getattr(est, "classifier", None):
        text += f" {est.classifier}"
        asked = getattr(est, "latch_model", "classifier")
        if asked in ("event", "local_event"):  # the law asked for could not be fitted
            names = [est.feature_names_[j] for j in getattr(est, "classifier_columns_", [])]
            if names and all(re.fullmatch(r"x\d+", n) for n in names):
                why = "fitted on a feature array, whose columns have no names"
            elif not event_features(names):
                why = "the features lack the current, its rate or the direction the law needs"
            else:
                why = "fewer than two latch-on and two latch-off events in the training data"
            text += f" (in place of the {LATCH_NAMES.get(asked, asked)}: {why})"
    acc = getattr(est, "classifier_train_accuracy_", None)
    return text + (f"; training latch-state accuracy {100 * acc:.2f} %" if acc is not None else "")
