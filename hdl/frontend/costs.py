"""The word generator's former module name, kept for the formal wrappers (``hdl/formal`` imports
``WordGenerator`` and ``pixel_features_layout`` from here): everything lives in :mod:`.words`."""

from .words import WordGenerator, check_frontend_params, check_frontend_types, pixel_features_layout

__all__ = ["WordGenerator", "check_frontend_params", "check_frontend_types", "pixel_features_layout"]
