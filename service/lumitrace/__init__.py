"""lumitrace: far-field luminous intensity of OpenUSD luminaires by photon tracing.

Importing the package registers the lumitrace USD schema plugin, so it must happen before
any stage is composed (late registration is silently ignored by USD).
"""
from .schema import register_schema

register_schema()

__version__ = "0.1.0"
