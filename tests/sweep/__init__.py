"""Tests of `twinfleet sweep` (twinfleet/sweep/)."""
