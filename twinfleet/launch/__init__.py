"""Scenarios shipped with twinfleet: `twinfleet launch c1a` and `twinfleet examples` find them here."""
