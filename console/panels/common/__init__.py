"""Panels both arms build: jog, readout, hardware, session, view."""
