"""Measurements behind `irring bench`; each returns plain dicts of figures."""
