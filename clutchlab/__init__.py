"""clutchlab: physics-hybrid grey-box models of clutch control pressure from test-stand data."""

__version__ = "0.1.0"
