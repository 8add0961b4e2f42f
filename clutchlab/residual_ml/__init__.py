"""Residual machine learning: the paper's features, latch classifiers and local GPs.

Empty at this stage of the project: the paper pipeline lands in its own issue.
"""

__all__: list[str] = []
